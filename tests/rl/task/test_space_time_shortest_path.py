"""The time-aware shortest path: breadth-first search over (cell, t mod T) with waiting, against known optima and
against a brute-force search over the MDP's own step function."""

from collections import deque

import numpy as np
import pytest

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.task.grid_mdp import MovingGridMDP
from dtradar_rl.task.twins import load_dataset

# A corridor (y = 1) with walls above and below, a niche below x = 3 and a longer way round over the top (y = 3):
#
#   y=3  . . . . . . .      the detour: 2 + 6 + 2 = 10 steps
#   y=2  . # # # # # .
#   y=1  S . . m . . T      the corridor: 6 steps, but a mover stands on (3, 1) at snapshots 0-3
#   y=0  # # # n # # #      ... and steps into its niche (3, 0) at snapshots 4-7
WALLS = np.array(
    [
        [1, 1, 1, 0, 1, 1, 1],
        [0, 0, 0, 0, 0, 0, 0],
        [0, 1, 1, 1, 1, 1, 0],
        [0, 0, 0, 0, 0, 0, 0],
    ],
    bool,
)


@pytest.fixture(scope="module")
def corridor():
    blocked = np.repeat(WALLS[None], 8, 0)
    blocked[:4, 1, 3] = True  # in the corridor
    blocked[4:, 0, 3] = True  # in its niche
    return MovingGridMDP.from_masks(blocked, name="corridor")


def cell(mdp, ix, iy):
    return mdp.cell(ix, iy)


def test_waiting_for_the_mover_beats_the_detour(corridor):
    s, t = cell(corridor, 0, 1), cell(corridor, 6, 1)
    assert corridor.bfs_distances(t)[s] == 6  # the static map ignores the mover
    assert corridor.space_time_distance(s, t, t0=0) == 7  # one wait: reach (3, 1) at snapshot 4, not 3
    path = corridor.space_time_shortest_path(s, t, t0=0)
    assert len(path) == 8 and path[0] == s and path[-1] == t
    waits = [a for a, b in zip(path, path[1:]) if a == b]
    assert len(waits) == 1 and all(corridor.xy(c)[1] == 1 for c in path)  # stays in the corridor
    for k, c in enumerate(path):  # never on a covered cell
        assert not corridor.covered[k % 8, c]


def test_a_start_later_in_the_period_needs_no_wait_and_waits_wrap_around(corridor):
    s, t = cell(corridor, 0, 1), cell(corridor, 6, 1)
    assert corridor.space_time_distance(s, t, t0=4) == 6  # the niche is taken by the time the robot comes
    # from snapshot 6 the robot could reach (3, 1) at snapshot 9 = 1: the mover is back there until 12 = 4 mod 8
    assert corridor.space_time_distance(s, t, t0=6) == 9  # three waits
    assert corridor.space_time_distance(s, t, t0=7) == 8  # two waits
    # from snapshot 5 it would wait four steps (10 in all): as long as the way over the top
    assert corridor.space_time_distance(s, t, t0=5) == 10
    path = corridor.space_time_shortest_path(s, t, t0=5)
    assert len(path) == 11 and path[-1] == t


def test_with_the_corridor_walled_in_bump_waiting_is_as_short_as_free_waiting(corridor):
    free = corridor.space_time_distances_many([cell(corridor, 6, 1)], "free")
    bump = corridor.space_time_distances_many([cell(corridor, 6, 1)], "bump")
    s = cell(corridor, 0, 1)
    np.testing.assert_array_equal(free[0, :, s], bump[0, :, s])
    reach = bump >= 0
    assert (free[reach] <= bump[reach]).all() and (free[reach] >= 0).all()
    with pytest.raises(UnknownNameError, match="waiting"):
        corridor.space_time_distances_many([0], "sometimes")


def test_the_search_is_the_mdps_own_optimum_on_a_synthetic_moving_twin():
    """Breadth-first over the env's step function (waiting only by bumping, never into a hit) gives the same
    distances as the batched search with ``waiting="bump"``; free waiting is never longer."""
    mdp = MovingGridMDP.from_dataset(load_dataset("synthetic-moving-12x8/blueprint"))
    t_count = mdp.snapshots
    rng = np.random.default_rng(0)
    targets = rng.choice(mdp.pair_cells(), 4, replace=False)
    bump = mdp.space_time_distances_many(targets, "bump")
    free = mdp.space_time_distances_many(targets, "free")
    for k, target in enumerate(targets):
        for start in rng.choice(np.flatnonzero(mdp.free), 6, replace=False):
            for t0 in range(t_count):
                if mdp.covered[t0, start]:
                    continue
                assert bump[k, t0, start] == _brute_force(mdp, int(start), int(target), t0)
                assert free[k, t0, start] <= bump[k, t0, start] or bump[k, t0, start] < 0


def test_a_bump_waiting_path_can_be_walked_with_the_four_moves():
    mdp = MovingGridMDP.from_dataset(load_dataset("synthetic-moving-12x8/blueprint"))
    episodes = mdp.sample_episodes(20, np.random.default_rng(3), waiting="bump")
    for s, t, t0 in episodes:
        path = mdp.space_time_shortest_path(int(s), int(t), int(t0), waiting="bump")
        cell, time = int(s), int(t0)
        for nxt in path[1:]:
            moves = [mdp.step_at(cell, time, a) for a in range(4)]
            cell, time, _, _, hit = next(m for m in moves if m[0] == nxt and not m[4])
            assert not hit
        assert cell == t and len(path) - 1 == mdp.space_time_distance(int(s), int(t), int(t0), "bump")


def test_sampled_episodes_start_free_and_can_reach_their_target():
    mdp = MovingGridMDP.from_dataset(load_dataset("synthetic-moving-12x8/blueprint"))
    eps = mdp.sample_episodes(50, np.random.default_rng(0))
    assert eps.shape == (50, 3) and (eps[:, 0] != eps[:, 1]).all()
    assert not mdp.covered[eps[:, 2], eps[:, 0]].any()
    d = np.array([mdp.space_time_distance(s, t, t0) for s, t, t0 in eps])
    assert (d > 0).all()
    np.testing.assert_array_equal(eps, mdp.sample_episodes(50, np.random.default_rng(0)))


def _brute_force(mdp: MovingGridMDP, start: int, target: int, t0: int) -> int:
    """Fewest steps by plain BFS over (cell, t) with :meth:`MovingGridMDP.step_at` (hits excluded); -1: never."""
    t_count = mdp.snapshots
    seen = {(start, t0 % t_count)}
    queue = deque([(start, t0 % t_count, 0)])
    while queue:
        c, t, d = queue.popleft()
        if c == target:
            return d
        for a in range(4):
            nxt, t1, _, _, hit = mdp.step_at(c, t, a)
            if not hit and (nxt, t1) not in seen:
                seen.add((nxt, t1))
                queue.append((nxt, t1, d + 1))
    return -1
