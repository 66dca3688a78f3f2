"""The navigation MDP: moves, collisions, connectivity, shortest paths, and every term of the paper reward."""

from collections import deque

import numpy as np
import pytest

from dtradar_data.core.errors import UnknownNameError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.grid_mdp import GridMDP, NoConnectedPairError, default_max_steps
from dtradar_rl.task.rewards import reward_fn

X_MINUS, X_PLUS, Y_MINUS, Y_PLUS = range(4)


def two_rooms():
    """7 x 5 grid; a wall at ix = 3 with no gap splits it into two rooms; one more blocked cell at (6, 0)."""
    b = np.zeros((5, 7), bool)
    b[:, 3] = True
    b[0, 6] = True
    return b


def env_on(blocked, **kw):
    ny, nx = blocked.shape
    return DtradarNavEnv(synthetic_dataset(nx, ny, blocked), **kw)


def test_paper_reward_is_minus_squared_distance_after_the_move():
    env = env_on(np.zeros((5, 7), bool), reward="paper")
    env.reset(seed=0, options={"start": (0, 0), "target": (5, 3)})
    _, r, terminated, truncated, info = env.step(X_PLUS)  # now at (1, 0): dx = 4, dy = 3
    assert r == -(4**2 + 3**2)
    assert not terminated and not truncated and not info["collision"]


def test_paper_reward_adds_5000_on_reaching_the_target_and_terminates():
    env = env_on(np.zeros((5, 7), bool), reward="paper")
    env.reset(seed=0, options={"start": (4, 3), "target": (5, 3)})
    _, r, terminated, truncated, info = env.step(X_PLUS)
    assert r == 5000.0 and terminated and not truncated and info["is_success"]


def test_collision_costs_5000_and_the_robot_stays_in_place():
    env = env_on(two_rooms(), reward="paper")
    env.reset(seed=0, options={"start": (2, 1), "target": (0, 1)})
    _, r, terminated, _, info = env.step(X_PLUS)  # into the wall at ix = 3
    assert info["collision"] and info["cell"] == (2, 1)
    assert r == -(2**2) - 5000.0 and not terminated
    _, r, _, _, info = env.step(Y_MINUS)  # (2, 0) is free
    _, r, _, _, info = env.step(Y_MINUS)  # off the grid
    assert info["collision"] and info["cell"] == (2, 0) and r == -(2**2 + 1) - 5000.0


def test_episodes_are_truncated_at_the_step_limit_not_terminated():
    env = env_on(np.zeros((5, 7), bool), reward="paper", max_steps=3)
    env.reset(seed=0, options={"start": (0, 0), "target": (6, 4)})
    flags = [env.step(X_MINUS)[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]


def test_default_step_limit_is_four_times_the_grid_half_perimeter():
    assert default_max_steps(42, 18) == 240
    assert env_on(np.zeros((5, 7), bool)).max_steps == 48


@pytest.mark.parametrize("name", ["scaled", "euclidean", "geodesic"])
def test_shaped_rewards_reward_the_goal_and_punish_collisions(name):
    kw = dict(d2_after=0.0, pot_before=1.0, pot_after=0.0, diag2=74.0)
    assert reward_fn(name, collision=False, reached=True, **kw) > 0
    kw = dict(d2_after=4.0, pot_before=2.0, pot_after=2.0, diag2=74.0)
    assert reward_fn(name, collision=True, reached=False, **kw) < reward_fn(name, collision=False, reached=False, **kw)


def test_geodesic_reward_is_plus_one_along_a_shortest_path_around_a_wall():
    b = np.zeros((5, 7), bool)
    b[:4, 3] = True  # wall with a gap at the top row
    env = env_on(b, reward="geodesic")
    env.reset(seed=0, options={"start": (2, 0), "target": (4, 0)})
    _, r_up, *_ = env.step(Y_PLUS)  # the only way round is up
    _, r_down, *_ = env.step(Y_MINUS)
    assert r_up == 1.0 and r_down == -1.0


def test_unknown_reward_name_suggests_the_closest():
    with pytest.raises(UnknownNameError, match="geodesic"):
        env_on(np.zeros((3, 3), bool), reward="geodesc")


def test_sampled_pairs_are_connected_distinct_and_free():
    mdp = GridMDP.from_blocked(two_rooms())
    pairs = mdp.sample_pairs(400, np.random.default_rng(0))
    assert all(mdp.connected(s, t) and s != t for s, t in pairs)
    assert not mdp.blocked.ravel()[pairs].any()
    sides = {int(mdp.xy(s)[0] > 3) for s, _ in pairs}
    assert sides == {0, 1}  # both rooms are used


def test_isolated_cells_are_never_drawn():
    b = np.ones((3, 5), bool)
    b[1, 0] = False  # an isolated free cell
    b[1, 2:5] = False  # a corridor of three
    mdp = GridMDP.from_blocked(b)
    pairs = mdp.sample_pairs(50, np.random.default_rng(1))
    assert mdp.cell(0, 1) not in pairs


def test_a_grid_without_connected_cells_raises_a_typed_error():
    b = np.ones((3, 3), bool)
    b[1, 1] = False
    with pytest.raises(NoConnectedPairError):
        GridMDP.from_blocked(b).sample_pairs(1, np.random.default_rng(0))


def test_bfs_distance_goes_around_obstacles():
    b = np.zeros((5, 7), bool)
    b[:4, 3] = True
    mdp = GridMDP.from_blocked(b)
    d = mdp.bfs_distances(mdp.cell(4, 0))
    assert d[mdp.cell(2, 0)] == 2 + 4 * 2  # up 4, across 2, down 4
    assert d[mdp.cell(3, 0)] == -1  # blocked
    path = mdp.shortest_path(mdp.cell(2, 0), mdp.cell(4, 0))
    assert len(path) - 1 == 10 and path[0] == mdp.cell(2, 0) and path[-1] == mdp.cell(4, 0)


def test_many_target_bfs_matches_single_target_bfs():
    mdp = GridMDP.from_blocked(two_rooms())
    targets = np.flatnonzero(mdp.free)[:6]
    many = mdp.bfs_distances_many(targets)
    for k, t in enumerate(targets):
        np.testing.assert_array_equal(many[k], mdp.bfs_distances(int(t)))


def _deque_bfs(blocked: np.ndarray, target: int) -> np.ndarray:
    """The textbook breadth-first search, one cell at a time: the oracle of the compiled one. A blocked cell has no
    moves in or out (a blocked target is only at distance 0 from itself)."""
    h, w = blocked.shape
    dist = np.full(h * w, -1, np.int64)
    dist[target] = 0
    queue = deque([] if blocked.flat[target] else [target])
    while queue:
        u = queue.popleft()
        y, x = divmod(u, w)
        for vy, vx in ((y, x - 1), (y, x + 1), (y - 1, x), (y + 1, x)):
            v = vy * w + vx
            if 0 <= vy < h and 0 <= vx < w and not blocked[vy, vx] and dist[v] < 0:
                dist[v] = dist[u] + 1
                queue.append(v)
    return dist


def test_compiled_bfs_equals_a_textbook_bfs_on_random_grids_with_walls_islands_and_blocked_targets():
    rng = np.random.default_rng(7)
    for h, w, p in ((1, 9, 0.2), (6, 11, 0.3), (13, 8, 0.45)):
        blocked = rng.random((h, w)) < p
        mdp = GridMDP.from_blocked(blocked)
        targets = np.arange(h * w)  # free and blocked targets alike
        many = mdp.bfs_distances_many(targets)
        for t in targets:
            np.testing.assert_array_equal(many[t], _deque_bfs(blocked, int(t)))


def test_bfs_to_no_targets_is_an_empty_table():
    mdp = GridMDP.from_blocked(two_rooms())
    assert mdp.bfs_distances_many(np.array([], np.int64)).shape == (0, mdp.num_cells)
