"""The wait action (action 4): it stays on the cell, is never a collision, is still a mover hit when a mover walks
onto the robot, is rewarded as a step that ends where it began without the collision penalty, and the space-time
shortest path with free waiting is the optimum of a robot that has it."""

from collections import deque

import numpy as np
import pytest
import torch

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv, InvalidActionError
from dtradar_rl.task.grid_mdp import WAIT, GridMDP, MovingGridMDP
from dtradar_rl.task.twins import load_dataset


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def lane(positions) -> MovingGridMDP:
    """A 4 x 1 lane, one mover at ``positions[t]`` (a cell index, or None) in snapshot t."""
    blocked = np.zeros((len(positions), 1, 4), bool)
    for t, p in enumerate(positions):
        if p is not None:
            blocked[t, 0, p] = True
    return MovingGridMDP.from_masks(blocked, name="lane")


def test_the_wait_is_action_four_and_stays_on_the_cell_without_a_collision():
    mdp = GridMDP.from_blocked(np.zeros((2, 3), bool))
    assert WAIT == 4
    assert mdp.step(2, WAIT) == (2, False)


def test_a_wait_on_a_free_cell_is_no_collision_and_a_mover_walking_onto_it_is_a_hit():
    mdp = lane([3, 2, 1])  # the mover walks from cell 3 towards cell 0
    assert mdp.step_at(0, 0, WAIT) == (0, 1, False, False, False)  # the next snapshot leaves cell 0 free
    assert mdp.step_at(1, 1, WAIT) == (1, 2, False, False, True)  # it walks onto the robot that waits
    # the same move into the mover would have been a mover collision: the wait never is
    assert mdp.step_at(1, 0, 1)[3] and not mdp.step_at(1, 0, WAIT)[3]


def _optimum_with_waits(mdp: MovingGridMDP, target: int) -> np.ndarray:
    """Brute force over step_at with the five actions: the fewest steps to ``target`` without a collision or a hit."""
    t_count, n = mdp.snapshots, mdp.num_cells
    # predecessors of (cell, t): every (c, s) with one action leading there cleanly
    pred = [[[] for _ in range(n)] for _ in range(t_count)]
    for s in range(t_count):
        for c in np.flatnonzero(mdp.free_at(s)):
            for a in range(5):
                nxt, t1, wall, mover, hit = mdp.step_at(int(c), s, a)
                if not (wall or mover or hit) and (a == WAIT or nxt != c):
                    pred[t1][nxt].append((int(c), s))
    dist = np.full((t_count, n), -1)
    queue = deque()
    for t in range(t_count):
        dist[t, target] = 0
        queue.append((target, t))
    while queue:
        c, t = queue.popleft()
        for pc, ps in pred[t][c]:
            if dist[ps, pc] < 0:
                dist[ps, pc] = dist[t, c] + 1
                queue.append((pc, ps))
    return dist


def test_the_space_time_optimum_with_free_waiting_is_that_of_a_robot_with_the_wait_action(moving):
    mdp = MovingGridMDP.from_dataset(moving)
    for target in mdp.pair_cells()[::17]:
        got = mdp.space_time_distances(int(target), waiting="free")
        want = _optimum_with_waits(mdp, int(target))
        starts = ~mdp.covered  # a robot starts on a cell free in its snapshot
        np.testing.assert_array_equal(np.where(starts, got, -2), np.where(starts, want, -2))


def _wall_bump(mdp: GridMDP) -> tuple[int, int]:
    """A free cell and a move from it into a wall or the grid's edge."""
    cell, action = np.argwhere(mdp.collides & mdp.free[:, None])[0]
    return int(cell), int(action)


@pytest.mark.parametrize("reward", ["paper", "scaled", "geodesic"])
def test_a_wait_is_rewarded_as_a_bump_without_the_collision_penalty(reward):
    ds = load_dataset("synthetic-12x8/blueprint")
    env = DtradarNavEnv(ds, reward=reward, wait_action=True)
    cell, action = _wall_bump(env.mdp)
    target = next(int(c) for c in env.mdp.pair_cells() if c != cell and env.mdp.connected(c, cell))
    options = {"start": env.mdp.xy(cell), "target": env.mdp.xy(target)}
    env.reset(options=options)
    _, bump, _, _, info = env.step(action)
    assert info["collision"]
    env.reset(options=options)
    _, wait, _, _, info = env.step(WAIT)
    assert not info["collision"] and env.mdp.cell(*info["cell"]) == cell
    penalty = 5000.0 if reward == "paper" else 1.0
    assert wait == pytest.approx(bump + penalty, rel=1e-5, abs=1e-6)  # float32 rewards


def test_without_the_option_the_envs_keep_four_actions_and_refuse_the_wait():
    ds = load_dataset("synthetic-12x8/blueprint")
    env = DtradarNavEnv(ds)
    env.reset(seed=0)
    assert env.action_space.n == 4
    with pytest.raises(InvalidActionError, match="0..3"):
        env.step(WAIT)
    batched = BatchedNavEnv.from_dataset(ds, 2)
    assert batched.num_actions == 4 and batched._step_cell is batched.next_cell


def test_the_batched_env_waits_on_a_static_twin_as_the_gymnasium_env_does():
    ds = load_dataset("synthetic-12x8/blueprint")
    n = 8
    batched = BatchedNavEnv.from_dataset(ds, n, reward="geodesic", seed=2, wait_action=True)
    assert not batched._fast_step  # the fast path's tables have four moves
    pairs = batched.mdp.sample_pairs(n, np.random.default_rng(1))
    batched.reset_where(torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    envs = [DtradarNavEnv(ds, reward="geodesic", wait_action=True) for _ in range(n)]
    for e, (s, t) in zip(envs, pairs):
        e.reset(options={"start": e.mdp.xy(s), "target": e.mdp.xy(t)})
    rng = np.random.default_rng(3)
    done = np.zeros(n, bool)
    for _ in range(20):
        actions = rng.integers(0, 5, n)
        obs_b, rew_b, term_b, _, info_b = batched.step(torch.as_tensor(actions))
        for i, e in enumerate(envs):
            if not done[i]:
                o, r, te, _, info = e.step(actions[i])
                np.testing.assert_allclose(obs_b[i].numpy(), o, rtol=1e-6)
                assert rew_b[i].item() == pytest.approx(r, abs=1e-6)
                assert bool(info_b["collision"][i]) == info["collision"]
                done[i] = te


def test_the_movers_penalty_charges_a_step_that_meets_a_mover_and_leaves_a_wall_bump_as_it_was(moving):
    mdp = MovingGridMDP.from_dataset(moving)
    t, c = next(
        (t, int(c))
        for t in range(mdp.snapshots)
        for c in np.flatnonzero(mdp.free_at(t))
        if mdp.step_at(int(c), t, WAIT)[4]
    )  # a mover walks onto a robot waiting on c
    target = next(int(x) for x in mdp.pair_cells() if x != c and mdp.connected(x, c))
    options = {"start": mdp.xy(c), "target": mdp.xy(target), "t0": t}
    rewards = {}
    for penalty in (1.0, 4.0):
        env = DtradarNavEnv(moving, reward="geodesic", wait_action=True, mover_penalty=penalty)
        env.reset(options=options)
        _, rewards[penalty], _, _, info = env.step(WAIT)
        assert info["mover_hit"]
    assert rewards[4.0] == pytest.approx(rewards[1.0] - 3.0)
