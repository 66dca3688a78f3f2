"""Observation presets, the gymnasium env and its registration, and the batched env against the single env."""

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from dtradar_data.core.errors import UnknownNameError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.envs.registration import register_dataset_envs
from dtradar_rl.task.observations import OBS_DIMS, PAPER_COLUMNS, Normalizer, build_observations
from dtradar_rl.task.twins import load_dataset, synthetic_blocked


@pytest.fixture(scope="module")
def small():
    return load_dataset("synthetic-12x8/blueprint")


@pytest.mark.parametrize("preset,dim", [("paper", 10), ("goal", 12), ("neighbors", 48)])
def test_observation_presets_have_the_documented_shapes(small, preset, dim):
    table = build_observations(small, preset, Normalizer.fit(small))
    assert OBS_DIMS[preset] == dim == table.dim == len(table.names)
    env = DtradarNavEnv(small, obs=preset)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (dim,) and obs.dtype == np.float32


def test_paper_preset_is_the_papers_ten_inputs_in_order(small):
    table = build_observations(small, "paper", Normalizer.fit(small))
    assert table.names == PAPER_COLUMNS
    assert table.names[:2] == ("x_m", "y_m") and "phase_rad" in table.names


def test_features_are_z_scored_with_the_stored_statistics(small):
    norm = Normalizer.fit(small)
    table = build_observations(small, "paper", norm)
    free = ~small.blocked.ravel()
    z = table.cell_part[free]
    assert np.allclose(z.mean(0), 0, atol=1e-4)
    assert Normalizer.from_dict(norm.to_dict()) == norm


def test_neighbor_flags_mark_blocked_and_off_grid_neighbours():
    b = np.zeros((3, 3), bool)
    b[1, 2] = True  # X+ of the centre is blocked
    ds = synthetic_dataset(3, 3, b)
    table = build_observations(ds, "neighbors", Normalizer.fit(ds))
    flags = [table.names.index(f"{a}:has_radio") for a in ("X-", "X+", "Y-", "Y+")]
    assert table.cell_part[4, flags].tolist() == [1, 0, 1, 1]  # centre cell
    assert table.cell_part[0, flags].tolist() == [0, 1, 0, 1]  # corner (0, 0): X- and Y- off the grid


def test_unknown_observation_preset_suggests_the_closest(small):
    with pytest.raises(UnknownNameError, match="neighbors"):
        DtradarNavEnv(small, obs="neighbours")


def test_every_registered_env_id_passes_the_gymnasium_checker(root):  # an empty data root: the synthetic ids
    ids = register_dataset_envs()
    for kind in ("", "-honest", "-privileged", "-privileged-memory"):
        assert f"dtradar/synthetic-blueprint{kind}-v0" in ids and f"dtradar/synthetic-dynamic{kind}-v0" in ids
    for eid in ids:
        env = gym.make(eid, obs="neighbors", reward="geodesic") if eid.endswith("-privileged-v0") else gym.make(eid)
        check_env(env.unwrapped, skip_render_check=True)
        env.close()


def test_the_plain_id_is_the_default_agents_honest_observation_and_position_is_named_privileged(root):
    from dtradar_rl.envs.honest_gym import HonestGymEnv
    from dtradar_rl.envs.memory import MemoryGymEnv

    register_dataset_envs()
    assert isinstance(gym.make("dtradar/synthetic-blueprint-v0").unwrapped, HonestGymEnv)
    assert isinstance(gym.make("dtradar/synthetic-blueprint-privileged-v0").unwrapped, DtradarNavEnv)
    assert isinstance(gym.make("dtradar/synthetic-blueprint-privileged-memory-v0").unwrapped, MemoryGymEnv)


def test_importing_dtradar_rl_registers_the_ids_without_importing_torch():
    code = (
        "import sys, dtradar_rl, gymnasium as gym; "
        "assert 'torch' not in sys.modules; "
        "assert 'dtradar/synthetic-blueprint-v0' in gym.registry; print('ok')"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


@pytest.mark.parametrize("obs", ["paper", "goal", "neighbors"])
def test_check_env_passes_for_every_preset(small, obs):
    check_env(DtradarNavEnv(small, obs=obs, render_mode="ansi"))


def test_render_shows_robot_target_and_obstacles(small):
    env = DtradarNavEnv(small, render_mode="ansi")
    env.reset(seed=0)
    text = env.render()
    assert text.count("R") == 1 and text.count("T") == 1 and "#" in text
    img = DtradarNavEnv(small, render_mode="rgb_array")
    img.reset(seed=0)
    assert img.render().shape == (8 * 8, 12 * 8, 3)


@pytest.mark.parametrize("reward", ["paper", "scaled", "euclidean", "geodesic"])
@pytest.mark.parametrize("obs", ["goal", "neighbors"])
def test_batched_env_equals_the_single_env_step_for_step(obs, reward):
    ds = load_dataset("synthetic-12x8/dynamic")
    norm = Normalizer.fit(ds)
    single = DtradarNavEnv(ds, obs=obs, reward=reward, normalizer=norm, max_steps=30)
    n = 16
    batched = BatchedNavEnv.from_dataset(ds, n, obs=obs, reward=reward, normalizer=norm, max_steps=30, seed=3)
    batched.reset()
    rng = np.random.default_rng(0)
    pairs = single.mdp.sample_pairs(n, rng)
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    envs = [DtradarNavEnv(ds, obs=obs, reward=reward, normalizer=norm, max_steps=30) for _ in range(n)]
    first = np.stack(
        [e.reset(options={"start": single.mdp.xy(s), "target": single.mdp.xy(t)})[0] for e, (s, t) in zip(envs, pairs)]
    )
    np.testing.assert_allclose(batched.observe().numpy(), first, rtol=1e-6)
    done = np.zeros(n, bool)
    for _ in range(30):
        actions = rng.integers(0, 4, n)
        obs_b, rew_b, term_b, trunc_b, info_b = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if done[i]:
                continue
            o, r, te, tr, info = e.step(actions[i])
            np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
            assert rew_b[i].item() == pytest.approx(r, rel=1e-5, abs=1e-5)
            assert (bool(term_b[i]), bool(trunc_b[i]), bool(info_b["collision"][i])) == (te, tr, info["collision"])
            done[i] = te or tr
    assert done.all()  # truncated at 30 at the latest


def test_batched_random_pairs_are_connected_and_distinct():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = BatchedNavEnv.from_dataset(ds, 2000, obs="goal", reward="paper", seed=1)
    env.reset()
    cell, target = env.cell.numpy(), env.target.numpy()
    assert (cell != target).all()
    assert all(env.mdp.connected(c, t) for c, t in zip(cell, target))


def test_synthetic_cubicle_stand_in_has_the_cubicle_grid_and_more_obstacles_when_dynamic():
    bp, dyn = synthetic_blocked(42, 18, "blueprint"), synthetic_blocked(42, 18, "dynamic")
    assert bp.shape == (18, 42) and bp.any() and (dyn & ~bp).any() and not (bp & ~dyn).any()


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_fresh_process_makes_an_env_by_gymnasiums_module_colon_id_form():
    import subprocess
    import sys

    code = (
        "import gymnasium as gym; env = gym.make('dtradar_rl.envs:dtradar/synthetic-blueprint-honest-v0');"
        "obs, info = env.reset(seed=0); print(obs.shape[0], 'x_m' in info['names'])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["20", "False"]
