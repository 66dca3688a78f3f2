"""On a moving twin the batched env and the gymnasium env agree step for step (observations at each robot's
snapshot, rewards, collisions, mover collisions and hits, the snapshot), with and without the wait action and the
clock; ``t0`` is checked like the other reset options; a static twin's envs are untouched."""

import math

import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryGymEnv, MemoryNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset

STEPS = 40


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def _episodes(env, n, seed=0):
    return env.mdp.sample_episodes(n, np.random.default_rng(seed))


@pytest.mark.parametrize(
    "obs,reward,noise,extra",
    [
        ("goal", "paper", "none", {}),
        ("neighbors", "geodesic", "none", {}),
        ("neighbors", "euclidean", "realistic", {}),
        ("goal", "paper", "none", {"wait_action": True}),
        ("neighbors", "geodesic", "none", {"wait_action": True, "clock": "sincos"}),
        ("neighbors", "scaled", "realistic", {"wait_action": True, "clock": "sincos"}),
        ("neighbors", "geodesic", "none", {"wait_action": True, "mover_penalty": 4.0}),
        ("goal", "paper", "none", {"mover_penalty": 0.5}),
    ],
)
def test_batched_and_gymnasium_envs_agree_step_for_step_on_a_moving_twin(moving, obs, reward, noise, extra):
    norm = Normalizer.fit(moving)
    n = 16
    kw = dict(obs=obs, reward=reward, normalizer=norm, max_steps=STEPS, noise=noise, **extra)
    batched = BatchedNavEnv.from_dataset(moving, n, seed=3, **kw)
    eps = _episodes(batched, n)
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=eps[:, 0], targets=eps[:, 1], t0=eps[:, 2])
    envs = [DtradarNavEnv(moving, **kw) for _ in range(n)]
    xy = batched.mdp.xy
    first = [e.reset(options={"start": xy(s), "target": xy(t), "t0": int(t0)}) for e, (s, t, t0) in zip(envs, eps)]
    assert batched.t.tolist() == [info["t"] for _, info in first] == eps[:, 2].tolist()
    if noise == "none":  # (with noise the two draw their errors from different streams)
        np.testing.assert_allclose(batched.observe().numpy(), np.stack([o for o, _ in first]), rtol=1e-6)
    rng = np.random.default_rng(0)
    done = np.zeros(n, bool)
    seen = {"mover_collision": 0, "mover_hit": 0}
    actions_count = 5 if extra.get("wait_action") else 4
    assert batched.num_actions == envs[0].action_space.n == actions_count
    for _ in range(STEPS):
        actions = rng.integers(0, actions_count, n)
        obs_b, rew_b, term_b, trunc_b, info_b = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if done[i]:
                continue
            o, r, te, tr, info = e.step(actions[i])
            if noise == "none":
                np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
                assert rew_b[i].item() == pytest.approx(r, rel=1e-5, abs=1e-5)
            got = tuple(bool(info_b[k][i]) for k in ("collision", "mover_collision", "mover_hit"))
            assert got == (info["collision"], info["mover_collision"], info["mover_hit"])
            assert (bool(term_b[i]), bool(trunc_b[i]), int(info_b["t"][i])) == (te, tr, info["t"])
            assert batched.cell[i].item() == batched.mdp.cell(*info["cell"])
            seen["mover_collision"] += info["mover_collision"]
            seen["mover_hit"] += info["mover_hit"]
            done[i] = te or tr
    assert done.all()
    assert seen["mover_collision"] > 0 and seen["mover_hit"] > 0  # the test did meet movers


@pytest.mark.parametrize("extra", [{}, {"wait_action": True, "clock": "sincos", "sense_radius": 3}])
def test_memory_envs_agree_step_for_step_on_a_moving_twin(moving, extra):
    n = 8
    kw = dict(obs="neighbors", reward="geodesic", max_steps=STEPS, memory_radius=2, memory_bumps=True, **extra)
    norm = Normalizer.fit(moving)
    batched = MemoryNavEnv.from_dataset(
        moving, n, normalizer=norm, seed=1, **{k: v for k, v in kw.items() if k != "obs"}
    )
    eps = _episodes(batched, n, seed=1)
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=eps[:, 0], targets=eps[:, 1], t0=eps[:, 2])
    envs = [MemoryGymEnv(moving, normalizer=norm, **kw) for _ in range(n)]
    xy = batched.mdp.xy
    first = np.stack(
        [e.reset(options={"start": xy(s), "target": xy(t), "t0": int(t0)})[0] for e, (s, t, t0) in zip(envs, eps)]
    )
    np.testing.assert_allclose(batched.observe().numpy(), first, rtol=1e-6)
    rng = np.random.default_rng(2)
    done = np.zeros(n, bool)
    for _ in range(STEPS):
        actions = rng.integers(0, batched.num_actions, n)
        obs_b, rew_b, term_b, trunc_b, _ = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if not done[i]:
                o, r, te, tr, _ = e.step(actions[i])
                np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
                assert rew_b[i].item() == pytest.approx(r, rel=1e-5, abs=1e-5)
                done[i] = te or tr


def test_the_moving_gymnasium_env_passes_the_checker_and_renders_movers(moving):
    env = DtradarNavEnv(moving, obs="neighbors", render_mode="ansi")
    check_env(env, skip_render_check=True)
    env.reset(seed=0)
    assert "M" in env.render()


def test_random_resets_start_on_a_cell_free_at_the_drawn_snapshot(moving):
    env = BatchedNavEnv.from_dataset(moving, 500, obs="goal", reward="paper", seed=4)
    env.reset()
    covered = env.mdp.covered
    t, cell, target = env.t.numpy(), env.cell.numpy(), env.target.numpy()
    assert not covered[t, cell].any() and (cell != target).all()
    assert len(set(t.tolist())) == env.mdp.snapshots  # every snapshot drawn
    env.reset_where(torch.ones(500, dtype=torch.bool), t0=2)  # t0 alone: random pairs, starts free at snapshot 2
    assert (env.t == 2).all() and not covered[2, env.cell.numpy()].any()
    gym_env = DtradarNavEnv(moving)
    for seed in range(20):
        _, info = gym_env.reset(seed=seed)
        assert not covered[info["t"], gym_env.mdp.cell(*info["cell"])]
    _, info = gym_env.reset(options={"t0": 3})
    assert info["t"] == 3 and not covered[3, gym_env.mdp.cell(*info["cell"])]


@pytest.mark.parametrize("bad", [1.5, math.nan, True, "1", (1,), None, -1, 6])
def test_a_malformed_t0_is_a_typed_error_naming_the_key(moving, bad):
    env = DtradarNavEnv(moving)
    _, before = env.reset(seed=0)
    with pytest.raises(InvalidCoordinatesError, match="'t0'"):
        env.reset(seed=1, options={"t0": bad})
    assert env._info(False)["cell"] == before["cell"]  # a refused reset changes nothing


def test_a_start_a_mover_covers_at_t0_is_refused_by_both_envs(moving):
    env = DtradarNavEnv(moving)
    mdp = env.mdp
    t0, start = (int(v) for v in np.argwhere(mdp.mover)[0])
    target = next(int(c) for c in mdp.pair_cells() if c != start and mdp.connected(c, start))
    with pytest.raises(InvalidCoordinatesError, match="covered by a mover"):
        env.reset(options={"start": mdp.xy(start), "target": mdp.xy(target), "t0": t0})
    batched = BatchedNavEnv.from_dataset(moving, 1)
    with pytest.raises(InvalidCoordinatesError, match="covered by a mover"):
        batched.reset_where(torch.ones(1, dtype=torch.bool), starts=[start], targets=[target], t0=t0)


def test_the_batched_env_checks_t0(moving):
    env = BatchedNavEnv.from_dataset(moving, 2)
    s, t, t0 = (int(v) for v in _episodes(env, 1)[0])
    mask = torch.ones(2, dtype=torch.bool)
    for bad, match in [
        ([t0 + 0.5, t0], "integer snapshot"),
        ([t0, t0, t0], "3 snapshots for 2"),
        (6, "0..5"),
        ("x", "t0"),
    ]:
        with pytest.raises(InvalidCoordinatesError, match=match):
            env.reset_where(mask, starts=[s, s], targets=[t, t], t0=bad)
    env.reset_where(mask, starts=[s, s], targets=[t, t], t0=[t0, t0])
    assert env.t.tolist() == [t0, t0]


def test_a_static_twin_has_one_snapshot_and_no_mover_keys():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = DtradarNavEnv(ds)
    s, t = env.mdp.sample_pairs(1, np.random.default_rng(0))[0]
    _, info = env.reset(options={"start": env.mdp.xy(s), "target": env.mdp.xy(t), "t0": 0})
    assert "t" not in info
    with pytest.raises(InvalidCoordinatesError, match="static twin has one snapshot"):
        env.reset(options={"t0": 1})
    _, _, _, _, info = env.step(0)
    assert set(info) == {"cell", "target", "collision", "is_success", "distance"}
    batched = BatchedNavEnv.from_dataset(ds, 2)
    assert not batched.moving and not hasattr(batched, "t") and "t" not in batched.state_keys
    batched.reset_where(torch.ones(2, dtype=torch.bool), t0=0)
    _, _, _, _, info = batched.step(torch.zeros(2, dtype=torch.long))
    assert set(info) == {"collision", "is_success", "steps"}
    with pytest.raises(InvalidCoordinatesError, match="static twin has one snapshot"):
        batched.reset_where(torch.ones(2, dtype=torch.bool), t0=1)
