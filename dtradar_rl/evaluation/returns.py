"""The return-based normalised score, D4RL's definition made exact: 0 = uniformly random moves, 100 = the optimum.

    from dtradar_rl.evaluation.returns import return_references, return_score
    refs = return_references(ds)                 # {"random": J_random, "optimal": J*, ...} on the 500 eval pairs
    return_score(J, refs)                        # 100 · (J − J_random) / (J* − J_random)

``J`` of a policy is its **discounted return from the start**, averaged over the twin's seeded evaluation pairs (the
500 pairs of seed 2024 of ``make eval`` and of the SPL-based score), under a reward (default ``geodesic``, what the
logged datasets use) and a discount (default :data:`~dtradar_rl.tabular.solver.GAMMA` = 0.9, the paper's, and the one
of the offline benchmark's FQE and true values). Both references are exact, not rolled out: ``J*`` is the mean of V*
(start, target) of the exact solution (:mod:`dtradar_rl.tabular.solver`), ``J_random`` the exact value of uniformly
random moves. A table policy's ``J`` is exact too (:mod:`dtradar_rl.tabular.evaluation`); any other policy's ``J``
is the mean discounted return of its rollouts, which differs from the infinite-horizon value by at most ``γ^cap``.

Why discounted: under the shaped rewards the undiscounted return telescopes (a ``geodesic`` episode that reaches its
target collects ``g(start) + 1`` whatever detours it took), so it cannot tell a shortest path from a long one; the
discounted return can, and its optimum is what the solver computes. The SPL-based score
(:mod:`dtradar_rl.evaluation.normalized`) stays the headline (bounded, reward-free); this one is its companion on the
scale D4RL and Minari define (``minari.get_normalized_score`` with the logged copies' ``ref_min_score`` /
``ref_max_score``, which are ``J_random`` / ``J*``, gives this score divided by 100).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.evaluation.normalized import DEFAULT_PAIRS, DEFAULT_SEED, twin_key
from dtradar_rl.tabular.evaluation import uniform_values
from dtradar_rl.tabular.solver import GAMMA, TabularMDP, solve
from dtradar_rl.task.config import ConfigError

_CACHE: dict[tuple, dict[str, Any]] = {}


def pair_values(tab: TabularMDP, values: np.ndarray, targets: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``float64[P]``: ``values[target row, start state]`` for every (start, target) pair (grid cells)."""
    rows = np.searchsorted(targets, pairs[:, 1])
    return values[rows, tab.states(pairs[:, 0])]


def return_references(
    ds: Dataset,
    *,
    reward: str = "geodesic",
    gamma: float = GAMMA,
    pairs: int = DEFAULT_PAIRS,
    seed: int = DEFAULT_SEED,
) -> dict[str, Any]:
    """``{"random", "optimal", "reward", "gamma", "pairs", "seed"}``: the exact mean discounted return of uniformly
    random moves and of the optimum on the evaluation pairs of ``ds``; cached in this process."""
    key = (twin_key(ds), reward, float(gamma), int(pairs), int(seed))
    if key not in _CACHE:
        tab = TabularMDP.from_dataset(ds)
        p = sample_eval_pairs(ds, pairs, seed)
        targets = np.unique(p[:, 1])
        star = solve(tab, reward, gamma, targets)
        rand = uniform_values(tab, targets, reward, gamma)
        _CACHE[key] = {
            "random": float(pair_values(tab, rand, targets, p).mean()),
            "optimal": float(pair_values(tab, star.values, targets, p).mean()),
            "reward": reward,
            "gamma": float(gamma),
            "pairs": int(pairs),
            "seed": int(seed),
        }
    return dict(_CACHE[key])


def return_score(value: float, refs: dict[str, Any]) -> float:
    """``100 · (J − J_random) / (J* − J_random)``."""
    lo, hi = float(refs["random"]), float(refs["optimal"])
    if not hi > lo:
        raise ConfigError(
            f"the optimal return ({hi:.4f}) does not exceed the random policy's ({lo:.4f}): no return-based score",
            hint="check the reward and the twin's connected cells",
        )
    return 100.0 * (float(value) - lo) / (hi - lo)


__all__ = ["pair_values", "return_references", "return_score"]
