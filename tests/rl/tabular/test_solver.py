"""The exact solution of a twin: V*/Q* equal brute-force value iteration on tiny grids, the greedy policy walks
breadth-first shortest paths under the geodesic reward, the cache is keyed by twin, reward and discount, and bad
input is refused before any work."""

import itertools

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.tabular import solver
from dtradar_rl.tabular.cache import solve_twin
from dtradar_rl.tabular.evaluation import follow, path_metrics, policy_values
from dtradar_rl.tabular.solver import TabularMDP, solve
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.rewards import REWARDS, reward_fn
from dtradar_rl.task.twins import load_dataset


def walls(seed: int, h: int = 5, w: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    blocked = rng.random((h, w)) < 0.25
    blocked[0, 0] = False
    return blocked


def brute_force_q(mdp: GridMDP, reward: str, gamma: float, target: int, sweeps: int = 3000) -> np.ndarray:
    """Textbook value iteration, one (cell, action) at a time, with the env's reward function."""
    free = np.flatnonzero(mdp.free)
    dist = mdp.bfs_distances(target)
    v = dict.fromkeys(free.tolist(), 0.0)
    q = {}
    for _ in range(sweeps):
        for c, a in itertools.product(free.tolist(), range(4)):
            nxt, col = mdp.step(c, a)
            pot = lambda x: max(dist[x], 0) if reward == "geodesic" else float(np.sqrt(mdp.d2(x, target)))  # noqa: E731
            r = reward_fn(
                reward,
                d2_after=float(mdp.d2(nxt, target)),
                pot_before=pot(c),
                pot_after=pot(nxt),
                collision=col,
                reached=nxt == target,
                diag2=mdp.diag2,
            )
            q[c, a] = r + (0.0 if nxt == target else gamma * v[nxt])
        v = {c: max(q[c, a] for a in range(4)) for c in free.tolist()}
    return np.array([[q[c, a] for a in range(4)] for c in free])


@pytest.mark.parametrize("reward", REWARDS)
def test_q_star_equals_brute_force_value_iteration_on_a_tiny_grid(reward):
    mdp = GridMDP.from_blocked(walls(1, 4, 5))
    tab = TabularMDP.from_mdp(mdp)
    target = int(tab.cells[-1])
    sol = solve(tab, reward, 0.8, [target])
    want = brute_force_q(mdp, reward, 0.8, target, sweeps=400)
    got = sol.q()[0]
    reachable = mdp.bfs_distances(target)[tab.cells] >= 0
    np.testing.assert_allclose(got[reachable], want[reachable], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("gamma", [0.5, 0.9, 0.99])
def test_the_greedy_policy_walks_breadth_first_shortest_paths_under_the_geodesic_reward(seed, gamma):
    mdp = GridMDP.from_blocked(walls(seed, 9, 11))
    tab = TabularMDP.from_mdp(mdp)
    sol = solve(tab, "geodesic", gamma)
    g = sol.greedy()
    d = mdp.bfs_distances_many(sol.targets)[:, tab.cells]  # [K, N]
    after = d[np.arange(len(sol.targets))[:, None], tab.next[np.arange(tab.n)[None, :], g]]
    reach = d > 0
    assert (after[reach] == d[reach] - 1).all()  # every greedy move shortens the breadth-first distance by one
    pairs = mdp.sample_pairs(200, np.random.default_rng(seed))
    rows = np.searchsorted(sol.targets, pairs[:, 1])
    m = path_metrics(follow(tab, g, rows, pairs[:, 0], pairs[:, 1], mdp.max_steps))
    assert m["success_rate"] == 1.0 and m["spl"] == 1.0


def test_the_greedy_policy_of_q_star_is_worth_v_star_exactly():
    tab = TabularMDP.from_mdp(GridMDP.from_blocked(walls(5, 8, 9)))
    for reward in ("paper", "geodesic"):
        sol = solve(tab, reward, 0.9)
        np.testing.assert_allclose(policy_values(tab, sol.greedy(), sol.targets, reward, 0.9), sol.values, rtol=1e-9)


def test_no_table_policy_beats_v_star():
    tab = TabularMDP.from_mdp(GridMDP.from_blocked(walls(2, 6, 6)))
    sol = solve(tab, "geodesic", 0.9)
    rng = np.random.default_rng(0)
    for _ in range(3):
        p = rng.random((sol.targets.size, tab.n, 4))
        v = policy_values(tab, p / p.sum(-1, keepdims=True), sol.targets, "geodesic", 0.9)
        assert (v <= sol.values + 1e-9).all()


def test_a_solution_is_cached_by_twin_reward_and_discount(root):
    ds = load_dataset("synthetic-10x6/blueprint")
    a, folder, cached = solve_twin(ds, "geodesic", 0.9)
    assert not cached and (folder / "solution.json").is_file() and (folder / "q.npy").is_file()
    b, _, cached = solve_twin(ds, "geodesic", 0.9)
    assert cached and np.array_equal(a.values, b.values)
    assert np.load(folder / "q.npy").shape == (a.targets.size, a.values.shape[1], 4)
    _, other, cached = solve_twin(ds, "geodesic", 0.5)
    assert not cached and other != folder
    (folder / "solution.json").write_text("{not json")  # a damaged cache is solved again, not trusted
    _, _, cached = solve_twin(ds, "geodesic", 0.9)
    assert not cached


def test_bad_input_is_refused_before_any_work(monkeypatch):
    tab = TabularMDP.from_mdp(GridMDP.from_blocked(walls(0)))
    with pytest.raises(InvalidSettingError, match="discount"):
        solve(tab, "geodesic", 1.0)
    with pytest.raises(Exception, match="reward"):
        solve(tab, "shortest", 0.9)
    blocked_cell = int(np.flatnonzero(~tab.mdp.free)[0])
    with pytest.raises(InvalidSettingError, match="blocked"):
        solve(tab, "geodesic", 0.9, [blocked_cell])
    monkeypatch.setattr(solver, "MAX_SOLUTION_BYTES", 1000)
    with pytest.raises(solver.TooLargeError, match="GiB"):
        solve(tab, "geodesic", 0.9)
    with pytest.raises(InvalidSettingError, match="moving twin"):
        TabularMDP.from_dataset(load_dataset("synthetic-moving-12x8/blueprint"))
