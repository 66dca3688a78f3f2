"""The compiled, cached space-time search: the same distances as the frontier propagation it replaced, computed once
per twin and target however many MDPs of the twin ask."""

import numpy as np
import pytest

from dtradar_rl.task import space_time
from dtradar_rl.task.grid_mdp import MovingGridMDP
from dtradar_rl.task.space_time import clear_space_time_cache


def frontier_distances(mdp: MovingGridMDP, targets, waiting: str) -> np.ndarray:
    """The previous implementation, kept as the reference: backward frontier propagation over (cell, t mod T), all
    targets at once."""
    targets = np.asarray(targets, np.int64)
    move_ok, wait_ok = space_time.transitions(mdp, waiting)
    t_count, n = mdp.covered.shape
    dist = np.full((targets.size, t_count, n), -1, np.int32)
    dist[np.arange(targets.size), :, targets] = 0
    frontier, step = dist == 0, 0
    while frontier.any():
        step += 1
        ahead = np.roll(frontier, -1, axis=1)
        reach = wait_ok[None] & ahead
        for a in range(4):
            reach |= move_ok[None, :, :, a] & ahead[:, :, mdp.next_cell[:, a]]
        new = reach & (dist < 0) & mdp.free[None, None]
        dist[new] = step
        frontier = new
    return dist


def random_twin(seed: int) -> MovingGridMDP:
    """Walls and movers at random: every case of the rules (swaps, covered targets, cut-off cells) turns up."""
    rng = np.random.default_rng(seed)
    t_count, h, w = int(rng.integers(2, 8)), int(rng.integers(3, 7)), int(rng.integers(3, 8))
    walls = rng.random((h, w)) < 0.15
    blocked = walls[None] | (rng.random((t_count, h, w)) < 0.2)
    return MovingGridMDP.from_masks(blocked, name=f"random-{seed}")


@pytest.fixture(autouse=True)
def empty_cache():
    clear_space_time_cache()
    yield
    clear_space_time_cache()


@pytest.mark.parametrize("waiting", ["free", "bump"])
def test_the_compiled_search_gives_the_frontier_propagations_distances_on_random_moving_twins(waiting):
    for seed in range(40):
        mdp = random_twin(seed)
        targets = np.arange(mdp.num_cells)  # every cell, static obstacles too (0 there, -1 elsewhere)
        np.testing.assert_array_equal(
            mdp.space_time_distances_many(targets, waiting), frontier_distances(mdp, targets, waiting)
        )


def test_each_target_is_searched_once_per_twin_whatever_mdp_of_the_twin_asks(monkeypatch):
    searched = []
    search = space_time._search
    monkeypatch.setattr(space_time, "_search", lambda grid, t, g: searched.extend(t.tolist()) or search(grid, t, g))
    twin = random_twin(3)
    first = twin.space_time_distances_many([4, 2, 4])
    again = MovingGridMDP.from_masks(twin.covered.reshape(-1, *twin.blocked.shape)).space_time_distances_many([2, 5])
    assert sorted(searched) == [2, 4, 5]  # a repeated target once, a known one not again
    np.testing.assert_array_equal(first[1], again[0])
    np.testing.assert_array_equal(first[0], first[2])


def test_a_twin_with_other_movers_or_waiting_rule_does_not_get_cached_distances():
    twin = random_twin(5)
    twin.space_time_distances_many(np.arange(twin.num_cells))
    covered = twin.covered.reshape(-1, *twin.blocked.shape).copy()
    covered[0] = covered[0].all()  # other movers, the same grid
    other = MovingGridMDP.from_masks(covered)
    targets = np.arange(other.num_cells)
    np.testing.assert_array_equal(other.space_time_distances_many(targets), frontier_distances(other, targets, "free"))
    np.testing.assert_array_equal(
        twin.space_time_distances_many(targets, "bump"), frontier_distances(twin, targets, "bump")
    )


def test_changing_a_returned_table_does_not_change_the_cache():
    twin = random_twin(7)
    first = twin.space_time_distances_many([1])
    expected = first.copy()
    first[:] = 99
    np.testing.assert_array_equal(twin.space_time_distances_many([1]), expected)


def test_a_cache_smaller_than_one_call_still_gives_every_distance(monkeypatch):
    monkeypatch.setattr(space_time.SPACE_TIME_TABLES, "max_bytes", 1)
    monkeypatch.setattr(space_time, "SPACE_TIME_CHUNK", 2)
    twin = random_twin(11)
    targets = np.arange(twin.num_cells)[::-1]
    np.testing.assert_array_equal(twin.space_time_distances_many(targets), frontier_distances(twin, targets, "free"))
    assert len(space_time.SPACE_TIME_TABLES) <= 1
