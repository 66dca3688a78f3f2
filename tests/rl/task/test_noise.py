"""Measurement noise: seeded, zero noise equals no noise, levels ordered, flags and positions untouched, and both
envs draw the same noise step for step."""

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.noise import NOISE_LEVELS, REALISTIC, RadioNoise, noise_model
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"


@pytest.fixture(scope="module")
def ds():
    return load_dataset(f"{SMALL}/dynamic")


def env(ds, noise, seed=3, n=64):
    e = BatchedNavEnv.from_dataset(ds, n, obs="neighbors", normalizer=Normalizer.fit(ds), seed=seed, noise=noise)
    e.reset()
    return e


def test_no_noise_changes_nothing_not_even_the_pairs_drawn(ds):
    plain = BatchedNavEnv.from_dataset(ds, 64, obs="neighbors", seed=3)
    plain.reset()
    quiet, noisy = env(ds, "none"), env(ds, "realistic")
    for e in (quiet, noisy):  # the noise has its own generator: the same pairs either way
        assert torch.equal(e.cell, plain.cell) and torch.equal(e.target, plain.target)
    assert torch.equal(quiet.observe(), plain.observe())
    assert not torch.equal(noisy.observe(), plain.observe())


def test_zero_errors_leave_every_observation_as_it_was(ds):
    norm = Normalizer.fit(ds)
    table = build_observations(ds, "neighbors", norm)
    noise = RadioNoise(REALISTIC, table, norm, torch.device("cpu"))
    cells = torch.arange(ds.shape[0] * ds.shape[1])
    obs = torch.from_numpy(table.observe(cells.numpy(), cells.numpy()))
    out = noise.apply(obs, cells, torch.zeros((len(cells), noise.groups, 7), dtype=torch.float64))
    torch.testing.assert_close(out, obs, rtol=1e-5, atol=1e-5)


def test_the_same_seed_gives_the_same_noise_and_another_seed_other_noise(ds):
    a, b, c = env(ds, "realistic"), env(ds, "realistic"), env(ds, "realistic", seed=4)
    assert torch.equal(a.observe(), b.observe())
    step = torch.zeros(64, dtype=torch.long)
    assert torch.equal(a.step(step)[0], b.step(step)[0])
    c.reset_where(torch.ones(64, dtype=torch.bool), starts=a.cell.numpy(), targets=a.target.numpy())
    assert not torch.allclose(a.observe(), c.observe())


def test_levels_are_ordered_and_leave_flags_positions_and_silent_cells_alone(ds):
    clean = env(ds, "none").observe()
    gaps = {}
    for level in NOISE_LEVELS:
        obs = env(ds, level).observe()
        gaps[level] = float((obs - clean).abs().mean())
        names = env(ds, level).obs_table.names
        fixed = [k for k, n in enumerate(names) if n.endswith("has_radio") or n in ("x_m", "y_m")] + [-2, -1]
        assert torch.equal(obs[:, fixed], clean[:, fixed])
        for a in ("X-", "X+", "Y-", "Y+"):  # a neighbour without radio keeps its zeros
            flag = obs[:, names.index(f"{a}:has_radio")] < 0.5
            cols = [k for k, n in enumerate(names) if n.startswith(f"{a}:") and not n.endswith("has_radio")]
            assert (obs[flag][:, cols] == 0).all()
    assert gaps["none"] == 0 < gaps["realistic"] < gaps["2x"]


def test_an_unknown_level_is_a_typed_error_with_a_suggestion():
    with pytest.raises(UnknownNameError, match="did you mean 'realistic'"):
        noise_model("realistc")
    assert noise_model(None) == NOISE_LEVELS["none"] and noise_model("2x").angle_deg == 2 * REALISTIC.angle_deg


@pytest.mark.parametrize("cls", [BatchedNavEnv, MemoryNavEnv])
def test_both_envs_draw_the_same_noise_step_for_step(ds, cls):
    norm = Normalizer.fit(ds)
    single = DtradarNavEnv(ds, obs="neighbors", reward="geodesic", normalizer=norm, max_steps=40, noise="realistic")
    kw = {"memory_radius": 3} if cls is MemoryNavEnv else {}
    batched = cls.from_dataset(
        ds, 1, obs="neighbors", reward="geodesic", normalizer=norm, max_steps=40, noise="realistic", seed=5, **kw
    )
    start, target = single.mdp.sample_pairs(1, np.random.default_rng(1))[0]
    o, _ = single.reset(seed=5, options={"start": single.mdp.xy(start), "target": single.mdp.xy(target)})
    batched.reset_where(torch.ones(1, dtype=torch.bool), starts=[start], targets=[target])
    np.testing.assert_allclose(batched.observe()[0, : len(o)].numpy(), o, rtol=1e-5, atol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(40):
        a = int(rng.integers(0, 4))
        o, _, te, tr, _ = single.step(a)
        ob, _, tb, rb, _ = batched.step(torch.as_tensor([a]))
        np.testing.assert_allclose(ob[0, : len(o)].numpy(), o, rtol=1e-5, atol=1e-6)
        assert (te, tr) == (bool(tb[0]), bool(rb[0]))
        if te or tr:
            break
