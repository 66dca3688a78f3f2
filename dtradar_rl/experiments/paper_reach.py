"""How far the paper's protocol stands from its Table VI pair, computed exactly on the twin, with no seed in it.

A training run of the paper's agent says "reached" or "not reached"; these numbers say why, from the pair's MDP itself
(the paper's reward, its γ = 0.9 and ε = 0.1, the run's episode cap):

* **The optimum of the paper's own MDP.** The pair's target is solved by value iteration
  (:mod:`dtradar_rl.tabular.solver`) and its greedy policy followed from the start. A learner that fits the paper's MDP
  perfectly acts like this; where it does not reach the target, no seed can reproduce the pair greedily, whatever its
  luck: the step cost ``-(dx² + dy²)`` at γ = 0.9 makes the optimum settle where the straight-line distance is small,
  and the +5 000 of the target, discounted over the detour, no longer pays for the way round a building.
* **Exploration within the cap.** The probability that one training episode hits the target within the cap, for a
  uniform random walk (an untrained agent: where every run starts) and for ε-greedy on that optimum (the best a trained
  agent explores with the paper's constant ε), and the steps an episode would take to hit it with probability 1/2
  and 0.99 without a cap: the cap that would bind in under 1 % of episodes. All from the absorbing Markov chain of
  that policy, solved exactly: no sampling.

Bumping into a wall keeps the cell (the MDP's collision), so the chains move exactly as the environment does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.sparse import csr_matrix

from dtradar_data.core.dataset import Dataset
from dtradar_rl.tabular.solver import GAMMA, TabularMDP, solve
from dtradar_rl.task.pairs import ResolvedPair
from dtradar_rl.train.config import config_for

#: The paper's constant exploration rate: the ``paper`` preset's (its ``eps_start`` = ``eps_end``).
EPSILON = config_for("paper").eps_end
#: Hitting-time quantiles reported: the median episode and the cap that would bind in under 1 % of episodes.
QUANTILES = (0.5, 0.99)
#: Steps the hitting-time distribution is followed at most (a quantile beyond is reported as "more than").
HORIZON = 200_000


def transition_matrix(tab: TabularMDP, probs: np.ndarray, target: int) -> csr_matrix:
    """``P[s, s']`` of the chain that takes move ``a`` with ``probs[s, a]``, the target state absorbing."""
    n = tab.n
    rows = np.repeat(np.arange(n), 4)
    p = np.asarray(probs, np.float64).reshape(-1).copy()
    cols = tab.next.reshape(-1).copy()
    at_target = rows == target
    cols[at_target] = target  # the target's four moves all stay there: their probabilities sum to 1
    return csr_matrix((p, (rows, cols)), shape=(n, n))


def hitting_times(p: csr_matrix, start: int, target: int, caps: tuple[int, ...]) -> dict[str, Any]:
    """``P(hit within cap)`` for each of ``caps`` and the steps of :data:`QUANTILES` (``None``: more than
    :data:`HORIZON`), following the chain's distribution from ``start`` step by step."""
    pt = p.T.tocsr()
    d = np.zeros(p.shape[0])
    d[start] = 1.0
    within: dict[int, float] = {}
    quantiles: dict[float, int | None] = dict.fromkeys(QUANTILES)
    last = max(caps)
    for step in range(1, HORIZON + 1):
        d = pt @ d
        hit = float(d[target])
        if step in caps:
            within[step] = hit
        for q in QUANTILES:
            if quantiles[q] is None and hit >= q:
                quantiles[q] = step
        if step >= last and quantiles[QUANTILES[-1]] is not None:
            break
    return {"within": within, "quantiles": quantiles}


def chain(
    tab: TabularMDP, actions: np.ndarray | None, start: int, target: int, caps: tuple[int, ...], epsilon: float
) -> dict[str, Any]:
    """:func:`hitting_times` of ε-greedy on the moves ``actions[state]`` (``None``: the uniform random walk), with
    its keys as strings, as ``report.json`` stores them."""
    probs = np.full((tab.n, 4), 0.25 if actions is None else epsilon / 4)
    if actions is not None:
        probs[np.arange(tab.n), actions] += 1.0 - epsilon
    h = hitting_times(transition_matrix(tab, probs, target), start, target, caps)
    return {
        "within": {str(c): h["within"].get(c) for c in caps},
        "quantiles": {str(q): h["quantiles"][q] for q in QUANTILES},
    }


def follow_greedy(tab: TabularMDP, actions: np.ndarray, start: int, target: int, dist: np.ndarray) -> dict[str, Any]:
    """The deterministic policy ``actions[state]`` from ``start``: reached and in how many steps, else the loop it
    settles in and that loop's nearest geodesic distance to the target (``dist`` per state)."""
    seen: dict[int, int] = {}
    s, path = start, [start]
    while s != target and s not in seen:
        seen[s] = len(path) - 1
        s = int(tab.next[s, actions[s]])
        path.append(s)
    if s == target:
        return {"reached": True, "steps": len(path) - 1, "settles": None, "closest": 0}
    loop = path[seen[s] :]
    return {
        "reached": False,
        "steps": None,
        "settles": [int(c) for c in tab.cells[loop[:-1]]],
        "closest": int(min(dist[x] for x in path)),
        "settles_at": int(min(dist[x] for x in loop)),
    }


def analyse(
    tab: TabularMDP, start_cell: int, target_cell: int, cap: int, *, gamma: float = GAMMA, epsilon: float = EPSILON
) -> dict[str, Any]:
    """What the MDP of the pair ``start_cell -> target_cell`` (grid cells) says of the paper's protocol with episodes
    capped at ``cap`` (module docstring): the optimum's greedy walk and the hitting times of the uniform and the
    ε-greedy-optimal chains within ``cap`` and 10 × ``cap``."""
    start, target = (int(x) for x in tab.states(np.array([start_cell, target_cell])))
    sol = solve(tab, "paper", gamma, np.array([target_cell]))
    greedy = sol.greedy()[0]
    dist = tab.mdp.bfs_distances(int(target_cell))[tab.cells]
    caps = (int(cap), 10 * int(cap))
    chains = {
        "uniform": chain(tab, None, start, target, caps, epsilon),
        "eps_optimal": chain(tab, greedy, start, target, caps, epsilon),
    }
    return {
        "gamma": gamma,
        "epsilon": epsilon,
        "shortest": int(dist[start]),
        "caps": list(caps),
        "optimum": follow_greedy(tab, greedy, start, target, dist),
        "chains": chains,
    }


def reach_analysis(ds: Dataset, pair: ResolvedPair, *, gamma: float = GAMMA, epsilon: float = EPSILON) -> dict:
    """:func:`analyse` of a placed Table VI pair on the twin ``ds``, with the pair's own episode cap."""
    s_cell, t_cell = pair.cells(ds.shape[1])
    out = analyse(TabularMDP.from_dataset(ds), s_cell, t_cell, pair.cap, gamma=gamma, epsilon=epsilon)
    return {"dataset": ds.name, "version": ds.version, **out}


def learned_chain(policy, ds: Dataset, start_cell: int, target_cell: int, cap: int, *, epsilon: float = EPSILON):
    """A trained fixed-pair agent's own chain: its greedy move on every free cell (its observation of a static twin
    depends on the cell alone), followed greedily from the start (as a greedy rollout goes) and ε-greedily (as its
    training explored): ``{"greedy": follow_greedy(...), "within": {cap, 10 x cap: P(hit)}, "quantiles": ...}``."""
    import torch

    tab = TabularMDP.from_dataset(ds)
    start, target = (int(x) for x in tab.states(np.array([start_cell, target_cell])))
    comp = tab.mdp.component[tab.cells]
    # an episode starts neither on its target nor where the target cannot be reached (the chain never goes there)
    others = np.flatnonzero((comp == comp[target]) & (np.arange(tab.n) != target))
    env = policy.env_for(ds, others.size, reward="paper")
    env.reset_where(
        torch.ones(others.size, dtype=torch.bool),
        starts=tab.cells[others],
        targets=np.full(others.size, int(target_cell)),
    )
    actions = np.zeros(tab.n, np.int64)
    actions[others] = policy.act(env.observe()).cpu().numpy()
    dist = tab.mdp.bfs_distances(int(target_cell))[tab.cells]
    caps = (int(cap), 10 * int(cap))
    return {
        "epsilon": epsilon,
        "greedy": follow_greedy(tab, actions, start, target, dist),
        **chain(tab, actions, start, target, caps, epsilon),
    }


def closest_approach(ds: Dataset, path: list[int], target_cell: int) -> dict[str, int]:
    """The nearest and the last breadth-first distance to the target along a rollout's ``path`` (grid cells)."""
    from dtradar_rl.task.grid_mdp import GridMDP

    d = GridMDP.from_dataset(ds).bfs_distances(int(target_cell))[np.asarray(path, np.int64)]
    d = d[d >= 0]
    return {"closest": int(d.min()) if d.size else -1, "end": int(d[-1]) if d.size else -1}


__all__ = [
    "EPSILON",
    "HORIZON",
    "QUANTILES",
    "analyse",
    "chain",
    "closest_approach",
    "follow_greedy",
    "hitting_times",
    "learned_chain",
    "reach_analysis",
    "transition_matrix",
]
