"""With a wider sensing radius the envs still agree: the batched env's fast path and general path bit for bit on a
static twin, the batched and gymnasium envs (plain and with memory) step for step on a moving twin, episodes
starting at snapshot 0 included; an augmented obstacle in the ring reads as blocked, now and a snapshot before."""

import numpy as np
import pytest
import torch

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryGymEnv, MemoryNavEnv, flag_columns
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.observations import Normalizer, ring_cells
from dtradar_rl.task.twins import load_dataset

pytestmark = pytest.mark.usefixtures("one_torch_thread")

RADIUS = 3
STEPS = 40


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def same_bits(a: torch.Tensor, b: torch.Tensor) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and torch.equal(a.view(torch.uint8), b.view(torch.uint8))


@pytest.mark.parametrize("cls, kw", [(BatchedNavEnv, {}), (MemoryNavEnv, {"memory_radius": 2, "memory_visits": True})])
def test_the_fast_path_and_the_general_path_agree_with_a_wider_radius(cls, kw):
    ds = load_dataset("synthetic-12x8/dynamic")
    common = dict(obs="neighbors", reward="geodesic", normalizer=Normalizer.fit(ds), max_steps=25, seed=4)
    fast = cls.from_dataset(ds, 48, sense_radius=RADIUS, **common, **kw)
    slow = cls.from_dataset(ds, 48, sense_radius=RADIUS, fast_path=False, **common, **kw)
    assert fast._fast_step and fast._fast_obs and not slow._fast_obs
    assert fast.obs_table.sense_radius == RADIUS and fast.obs_dim > 48 + (fast.layout.dim if kw else 0)
    gen = torch.Generator().manual_seed(0)
    assert same_bits(fast.reset(), slow.reset())
    for _ in range(80):
        a = torch.randint(4, (48,), generator=gen)
        out_f, out_s = fast.step(a), slow.step(a)
        for x, y in zip(out_f[:4], out_s[:4]):
            assert same_bits(x, y)
        done = out_f[2] | out_f[3]
        fast.reset_where(done), slow.reset_where(done)
        assert same_bits(fast.observe(), slow.observe())


@pytest.mark.parametrize(
    "batched_cls, gym_cls, kw",
    [
        (BatchedNavEnv, DtradarNavEnv, {}),
        (MemoryNavEnv, MemoryGymEnv, {"memory_radius": 2, "memory_bumps": True, "memory_visits": True}),
    ],
)
def test_batched_and_gymnasium_envs_agree_with_a_wider_radius_on_a_moving_twin(moving, batched_cls, gym_cls, kw):
    norm = Normalizer.fit(moving)
    n = 12
    common = dict(reward="geodesic", normalizer=norm, max_steps=STEPS, sense_radius=RADIUS, **kw)
    batched = batched_cls.from_dataset(moving, n, obs="neighbors", seed=3, **common)
    eps = moving_episodes(batched, n)
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=eps[:, 0], targets=eps[:, 1], t0=eps[:, 2])
    envs = [gym_cls(moving, obs="neighbors", **common) for _ in range(n)]
    xy = batched.mdp.xy
    first = [e.reset(options={"start": xy(s), "target": xy(t), "t0": int(t0)})[0] for e, (s, t, t0) in zip(envs, eps)]
    assert envs[0].observation_space.shape == (batched.obs_dim,)
    np.testing.assert_array_equal(batched.observe().numpy(), np.stack(first))
    rng = np.random.default_rng(0)
    done = np.zeros(n, bool)
    for _ in range(STEPS):
        actions = rng.integers(0, 4, n)
        obs_b = batched.step(torch.as_tensor(actions))[0]
        for i, e in enumerate(envs):
            if not done[i]:
                o, _, te, tr, _ = e.step(actions[i])
                np.testing.assert_array_equal(obs_b[i].numpy(), o)
                assert e.observation_space.contains(o)
                done[i] = te or tr
    assert done.all()


def moving_episodes(env, n: int) -> np.ndarray:
    """``n`` reachable episodes, the first ones starting at snapshot 0 (whose frame before is the last snapshot)."""
    eps = env.mdp.sample_episodes(4 * n, np.random.default_rng(5))
    at_zero = eps[eps[:, 2] == 0][:3]
    assert len(at_zero) == 3
    return np.concatenate([at_zero, eps[eps[:, 2] != 0][: n - 3]])


def test_an_augmented_obstacle_in_the_ring_reads_as_blocked_now_and_a_snapshot_before(moving):
    env = BatchedNavEnv.from_dataset(
        moving, 64, obs="neighbors", sense_radius=RADIUS, aug_obstacles=12, aug_obstacle_size=2, seed=1
    )
    env.reset()
    cols = env.obs_table.ring_columns
    rows = env._rows()
    table = env.cell_part[rows][:, cols]
    observed = env.observe()[:, cols]
    ring = torch.as_tensor(ring_cells(env.mdp.nx, env.mdp.ny, RADIUS))[env.cell]  # [N, K], -1 off the grid
    extra = env.extra.gather(1, ring.clamp(min=0)) & (ring >= 0)
    expect = table * (~extra).float().repeat(1, 2)
    assert torch.equal(observed, expect)
    k = ring.shape[1]
    assert bool((extra & (table[:, :k] > 0.5)).any())  # some obstacle did hide a cell the twin shows free
    # the four neighbours' flags are still where the memory env and the shield read them
    nbr = env.next_cell[env.cell]
    hidden = env.extra.gather(1, nbr)
    flags = env.observe()[:, flag_columns()]
    assert not bool((hidden & (flags > 0.5)).any())
