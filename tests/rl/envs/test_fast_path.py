"""The batched env's fast path (precomputed tables on a static twin) against its general path: the same
trajectories bit for bit (observations, rewards, terminations, info, state and random streams), for every reward,
observation preset and noise level, and when explicit targets grow the target pool."""

import numpy as np
import pytest
import torch

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryNavEnv
from dtradar_rl.task.observations import OBS_PRESETS, Normalizer
from dtradar_rl.task.rewards import REWARDS
from dtradar_rl.task.twins import load_dataset

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def assert_bits_equal(a, b, what: str) -> None:
    """Same dtype, shape and bytes (so -0.0 and 0.0 differ, and NaNs compare)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), what
        for k in a:
            assert_bits_equal(a[k], b[k], f"{what}[{k}]")
        return
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert torch.equal(a.contiguous().view(torch.uint8), b.contiguous().view(torch.uint8)), what


def pair(ds, cls=BatchedNavEnv, n=48, **kw):
    kw = {"normalizer": Normalizer.fit(ds), "max_steps": 25, "seed": 4, **kw}
    return cls.from_dataset(ds, n, **kw), cls.from_dataset(ds, n, fast_path=False, **kw)


def run_both(fast, slow, steps=120, seed=0, explicit=None):
    """Step both envs with the same random actions, resetting finished robots, and compare everything."""
    gen = torch.Generator().manual_seed(seed)
    assert_bits_equal(fast.reset(), slow.reset(), "first observation")
    for i in range(steps):
        a = torch.randint(4, (fast.num_envs,), generator=gen)
        out_f, out_s = fast.step(a), slow.step(a)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), out_f, out_s):
            assert_bits_equal(x, y, f"step {i}: {name}")
        done = out_f[2] | out_f[3]
        if explicit is not None and i % 10 == 5:  # explicit targets (some outside the pool), random starts
            k = int(done.sum())
            targets = explicit[torch.randint(len(explicit), (k,), generator=gen)]
            fast.reset_where(done, targets=targets), slow.reset_where(done, targets=targets)
        else:
            fast.reset_where(done), slow.reset_where(done)
        assert_bits_equal(fast.observe(), slow.observe(), f"step {i}: observe after reset")
        for k in fast.state_keys:
            assert_bits_equal(getattr(fast, k), getattr(slow, k), f"step {i}: state {k}")
    assert torch.equal(fast.gen.get_state(), slow.gen.get_state())
    assert torch.equal(fast.noise_gen.get_state(), slow.noise_gen.get_state())


@pytest.mark.parametrize("reward", REWARDS)
@pytest.mark.parametrize("obs", OBS_PRESETS)
def test_the_fast_path_and_the_general_path_give_identical_trajectories(obs, reward):
    ds = load_dataset("synthetic-12x8/dynamic")
    fast, slow = pair(ds, obs=obs, reward=reward)
    assert fast._fast_step and fast._fast_reset and fast._fast_obs
    assert not (slow._fast_step or slow._fast_reset or slow._fast_obs)
    run_both(fast, slow)


def test_with_measurement_noise_the_fast_step_and_reset_give_the_general_paths_trajectories():
    fast, slow = pair(load_dataset("synthetic-12x8/blueprint"), obs="neighbors", reward="geodesic", noise="realistic")
    assert fast._fast_step and fast._fast_reset and not fast._fast_obs  # noisy observations: the general observe
    run_both(fast, slow)


def test_explicit_targets_outside_the_pool_grow_the_fast_tables_and_keep_the_trajectories_equal():
    ds = load_dataset("synthetic-12x8/blueprint")
    fast, slow = pair(ds, obs="neighbors", reward="geodesic", target_pool=4)
    pool = fast.pool.numel()
    explicit = torch.as_tensor(fast.mdp.pair_cells()[::7])
    run_both(fast, slow, explicit=explicit)
    assert fast.pool.numel() > pool and fast._rtab.numel() == fast.pool.numel() * fast.mdp.num_cells * 4


def test_the_memory_env_on_the_fast_path_gives_the_general_paths_trajectories():
    ds = load_dataset("synthetic-12x8/dynamic")
    fast, slow = pair(ds, cls=MemoryNavEnv, obs="neighbors", memory_radius=2, memory_bumps=True, memory_visits=True)
    run_both(fast, slow, steps=60)


def test_out_of_range_actions_behave_as_on_the_general_path():
    fast, slow = pair(load_dataset("synthetic-12x8/blueprint"), n=4, obs="goal", reward="geodesic")
    fast.reset(), slow.reset()
    wrapped = torch.tensor([-1, -4, 3, 0])  # negative indices wrap, as they always did
    for x, y in zip(fast.step(wrapped), slow.step(wrapped)):
        assert_bits_equal(x, y, "wrapped actions")
    for bad in (torch.tensor([0, 4, 1, 2]), torch.tensor([0, -5, 1, 2])):
        for env in (fast, slow):
            with pytest.raises(IndexError):
                env.step(bad)


def test_the_fast_tables_equal_the_general_formulas():
    ds = load_dataset("synthetic-12x8/dynamic")
    env = BatchedNavEnv.from_dataset(ds, 1, obs="neighbors", reward="geodesic")
    n = env.mdp.num_cells
    rtab = env._rtab.view(env.pool.numel(), n, 4)
    d = env.dist.numpy().astype(np.float32)
    nxt, coll = env.mdp.next_cell, env.mdp.collides
    pool = env.pool.numpy()
    expect = d[:, :, None] - d[np.arange(pool.size)[:, None, None], nxt[None]]
    expect += (nxt[None] == pool[:, None, None]) - coll[None].astype(np.float32)
    free = ~env.mdp.blocked.ravel()
    np.testing.assert_array_equal(rtab.numpy()[:, free], expect[:, free])
