"""The exact solution of a static twin: V* and Q* for every (cell, target), by value iteration over all targets at once.

The navigation MDP is a lookup table: states are free cells, moves are deterministic
(:class:`~dtradar_rl.task.grid_mdp.GridMDP`), an episode ends on reaching the target, and every reward of
:data:`~dtradar_rl.task.rewards.REWARDS` is a function of (cell, action, target). So the goal-conditioned MDP is a
finite one per target, and Bellman's equation ``V(s) = max_a r(s, a, t) + γ · [s' != t] · V(s')`` can be solved
exactly for every target. Here it is solved for many targets at once: ``V`` is ``float64[K targets, N free cells]``,
one sweep is one gather ``V[:, next]`` and a max over the four moves, and the targets go in chunks of
:data:`CHUNK_BYTES`.

Exactness. The sweeps stop when no value moved by more than ``tol`` times the largest value (relative 1e-12 by
default): then every value is within ``tol · γ / (1 - γ)`` of V*, far below the gap between a shortest and a longer
path's values, so the greedy policy is optimal. :attr:`Solution.residual` records the last change. Under the
``geodesic`` reward, breadth-first shortest paths are optimal for every discount (its shaping gives +1 per step
along a shortest path, never more, and the bonus comes soonest), which ``tests/rl/tabular`` checks against
breadth-first distances and against brute-force value iteration on tiny grids; under the ``paper`` reward the optimum
prefers paths that stay near the target in straight-line distance, so its greedy SPL may fall below 1.

Q* is not stored separately in memory: moves are deterministic, so ``Q*(s, a) = r(s, a, t) + γ · [s' != t] ·
V*(s')`` exactly (:meth:`Solution.q`). :func:`dtradar_rl.tabular.cache.solve_twin` caches a solution on disk
(``<data root>/tabular/``), keyed by the twin's content version, the reward and the discount, each file with its
content hash: it is derived data, never part of the dataset.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError
from dtradar_rl.tabular.memory import CHUNK_BYTES, TooLargeError, check_memory, chunk_size, solve_parts
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.rewards import check_reward, reward_fn

#: The most a solution's values (float64 ``targets x cells``) may take; larger grids are refused up front.
MAX_SOLUTION_BYTES = 4 << 30
#: Relative change of the values below which the sweeps stop (module docstring).
TOL = 1e-12
#: A backstop far above what convergence needs (γ = 0.99 needs about 3 000 sweeps at 1e-12).
MAX_SWEEPS = 100_000
#: The discount of the exact solution and of the return-based scores: the paper's γ, and the one the offline
#: benchmark's FQE and true values use.
GAMMA = 0.9
FORMAT = "dtradar-tabular-solution/1"


@dataclass(frozen=True)
class TabularMDP:
    """The free cells of a twin and their moves in a compact numbering (``0..N-1``), plus what rewards need."""

    mdp: GridMDP
    #: ``int64[N]``: the grid cell of each state
    cells: np.ndarray
    #: ``int64[H*W]``: the state of each grid cell, -1 for blocked cells
    state_of: np.ndarray
    #: ``int64[N, 4]``: the state each move leads to (the same state on a collision)
    next: np.ndarray
    #: ``bool[N, 4]``: whether each move collides
    collides: np.ndarray

    @classmethod
    def from_mdp(cls, mdp: GridMDP) -> TabularMDP:
        cells = np.flatnonzero(mdp.free)
        state_of = np.full(mdp.num_cells, -1, np.int64)
        state_of[cells] = np.arange(cells.size)
        return cls(mdp, cells, state_of, state_of[mdp.next_cell[cells]], mdp.collides[cells])

    @classmethod
    def from_dataset(cls, ds: Dataset) -> TabularMDP:
        if ds.is_moving:
            raise InvalidSettingError(
                f"{ds.name} is a moving twin: the exact solution is for static twins (a moving twin's MDP is in "
                "space-time, its state a (cell, snapshot) pair)",
                hint="solve its blueprint or dynamic twin; SPL on a moving twin uses the space-time distances",
            )
        return cls.from_mdp(GridMDP.from_dataset(ds))

    @property
    def n(self) -> int:
        return int(self.cells.size)

    def states(self, cells: np.ndarray) -> np.ndarray:
        """The states of grid ``cells``; a cell number outside the grid (pairs of another twin) is an
        :class:`InvalidCoordinatesError`, a blocked cell an :class:`InvalidSettingError`."""
        cells = np.asarray(cells, np.int64)
        outside = (cells < 0) | (cells >= self.state_of.size)
        if outside.any():
            h, w = self.mdp.blocked.shape[-2:]
            raise InvalidCoordinatesError(
                f"{self.mdp.name}: cell {int(cells.ravel()[np.argmax(outside.ravel())])} is outside its {w} x {h} "
                f"grid (cells 0 to {self.state_of.size - 1})",
                hint=f"take the starts and targets from {self.mdp.name} itself (cell = y * {w} + x): pairs of "
                "another twin or scene number other cells",
            )
        s = self.state_of[cells]
        if (s < 0).any():
            raise InvalidSettingError(
                f"{self.mdp.name}: cell {int(np.asarray(cells).ravel()[np.argmax(s.ravel() < 0)])} is blocked",
                hint="targets and starts must be free cells",
            )
        return s

    def rewards(self, reward: str, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(float64[K, N, 4] r(s, a, t), bool[K, N, 4] reached)`` for the target states ``targets``.

        The env's own :func:`~dtradar_rl.task.rewards.reward_fn`, term for term; the geodesic potential is the
        breadth-first distance on this twin (0 for cells the target cannot be reached from: no pair starts there)."""
        targets = np.asarray(targets, np.int64)
        nxt = self.next
        reached = nxt[None, :, :] == targets[:, None, None]
        pot = np.zeros((targets.size, self.n))
        kind = check_reward(reward)
        if kind == "geodesic":
            pot = self.mdp.bfs_distances_many(self.cells[targets])[:, self.cells].astype(np.float64)
            pot[pot < 0] = 0.0
        x, y = self.mdp.xy(self.cells)
        dx, dy = x[None, :] - x[targets][:, None], y[None, :] - y[targets][:, None]
        d2 = (dx * dx + dy * dy).astype(np.float64)
        if kind == "euclidean":
            pot = np.sqrt(d2)
        rows = np.arange(targets.size)[:, None, None]
        r = reward_fn(
            kind,
            d2_after=d2[rows, nxt[None]],
            pot_before=pot[:, :, None],
            pot_after=pot[rows, nxt[None]],
            collision=self.collides[None],
            reached=reached,
            diag2=self.mdp.diag2,
        )
        return np.asarray(r, np.float64), reached


def check_size(n_targets: int, n_states: int, what: str = "solution") -> None:
    """Refuse up front a table of ``n_targets x n_states`` float64 values larger than :data:`MAX_SOLUTION_BYTES`."""
    need = n_targets * n_states * 8
    if need > MAX_SOLUTION_BYTES:
        raise TooLargeError(
            f"the {what} of {n_targets} targets x {n_states} cells needs {need / 2**30:.1f} GiB of float64 values, "
            f"above the {MAX_SOLUTION_BYTES / 2**30:.0f} GiB cap",
            hint="solve for fewer targets (targets=..., e.g. the evaluation pairs' targets) or a coarser grid",
        )


def check_gamma(gamma: float) -> float:
    if not (isinstance(gamma, (int, float)) and 0 < float(gamma) < 1):
        raise InvalidSettingError(f"the discount must be in (0, 1), got {gamma!r}", hint="e.g. 0.9 (the paper's)")
    return float(gamma)


def bellman_sweeps(
    r: np.ndarray,
    reached: np.ndarray,
    nxt: np.ndarray,
    gamma: float,
    *,
    allowed: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    floor: float | None = None,
    masked_value: float = -np.inf,
    forbidden: np.ndarray | None = None,
    tol: float = TOL,
) -> tuple[np.ndarray, int, float]:
    """Value iteration on one chunk: ``(V float64[K, N], sweeps, last relative change)``.

    ``allowed`` (``bool[N, 4]`` or ``[K, N, 4]``) removes moves: they are worth ``masked_value`` (default -inf: never
    taken; a state without any allowed move gets ``floor``, what a robot that can do nothing is worth); ``forbidden``
    (same shapes) removes moves whatever ``masked_value`` is (never taken: a move known to be blocked, where
    ``allowed`` keeps an unlogged move at ``masked_value``); ``v0`` starts the sweeps elsewhere than 0."""
    # action-major copies: one contiguous gather ``V[:, next[:, a]]`` per move is ~3x faster than one fancy
    # index over ``[K, N, 4]`` (measured on Dallas Q3's 1 950 states)
    r_a = np.ascontiguousarray(np.moveaxis(r, -1, 0))
    cont_a = np.ascontiguousarray(np.moveaxis(gamma * ~reached, -1, 0))
    nxt_a = [np.ascontiguousarray(nxt[:, a]) for a in range(nxt.shape[1])]
    mask_a = None
    stuck = None
    if allowed is not None:
        allowed = np.broadcast_to(allowed, r.shape)
        mask_a = np.ascontiguousarray(np.moveaxis(~allowed, -1, 0))
        stuck = ~allowed.any(-1) if masked_value == -np.inf else None
    forbid_a = None
    if forbidden is not None:
        forbidden = np.broadcast_to(forbidden, r.shape)
        forbid_a = np.ascontiguousarray(np.moveaxis(forbidden, -1, 0))
        gone = forbidden if allowed is None or masked_value != -np.inf else forbidden | ~allowed
        stuck = gone.all(-1) if stuck is None else stuck | gone.all(-1)
    v = np.zeros(r.shape[:2]) if v0 is None else np.array(v0, np.float64)
    new = np.empty_like(v)
    qa = np.empty_like(v)
    change = np.inf
    for sweep in range(1, MAX_SWEEPS + 1):
        for a, cells in enumerate(nxt_a):
            np.take(v, cells, axis=1, out=qa)
            qa *= cont_a[a]
            qa += r_a[a]
            if mask_a is not None:
                qa[mask_a[a]] = masked_value
            if forbid_a is not None:
                qa[forbid_a[a]] = -np.inf
            if a == 0:
                new[:] = qa
            else:
                np.maximum(new, qa, out=new)
        if stuck is not None:
            new[stuck] = floor if floor is not None else 0.0
        scale = max(1.0, float(np.abs(new).max()))
        change = float(np.abs(new - v).max()) / scale
        v, new = new, v
        if change <= tol:
            return v, sweep, change
    return v, MAX_SWEEPS, change


def expectation_sweeps(
    r: np.ndarray,
    reached: np.ndarray,
    nxt: np.ndarray,
    gamma: float,
    weights: np.ndarray,
    *,
    v0: np.ndarray | None = None,
    max_sweeps: int = MAX_SWEEPS,
    tol: float = TOL,
) -> tuple[np.ndarray, int, float]:
    """Policy evaluation on one chunk: ``V = Σ_a w_a · (r_a + γ · [not reached] · V[next_a])`` swept until the
    relative change is at most ``tol`` (or ``max_sweeps``); ``weights`` ``[K, N, 4]`` are the move probabilities
    (zero where a move must not count: its term is then 0). Action-major like :func:`bellman_sweeps`."""
    w_a = np.ascontiguousarray(np.moveaxis(np.broadcast_to(weights, r.shape), -1, 0))
    r_pi = (w_a * np.moveaxis(r, -1, 0)).sum(0)
    cont_a = w_a * np.moveaxis(gamma * ~reached, -1, 0)
    nxt_a = [np.ascontiguousarray(nxt[:, a]) for a in range(nxt.shape[1])]
    live = [a for a in range(len(nxt_a)) if cont_a[a].any()]
    v = np.zeros(r.shape[:2]) if v0 is None else np.array(v0, np.float64)
    qa = np.empty_like(v)
    change = np.inf
    for sweep in range(1, max_sweeps + 1):
        new = r_pi.copy()
        for a in live:
            np.take(v, nxt_a[a], axis=1, out=qa)
            qa *= cont_a[a]
            new += qa
        change = float(np.abs(new - v).max()) / max(1.0, float(np.abs(new).max()))
        v = new
        if change <= tol:
            return v, sweep, change
    return v, max_sweeps, change


@dataclass
class Solution:
    """V* of one twin for a set of targets, and how it was obtained."""

    name: str
    version: str
    reward: str
    gamma: float
    #: ``int64[K]``: the target cells (grid indices)
    targets: np.ndarray
    #: ``float64[K, N]``: V*(state, target), states in :attr:`TabularMDP.cells` order
    values: np.ndarray
    sweeps: int = 0
    residual: float = 0.0
    seconds: float = 0.0
    tab: TabularMDP | None = field(default=None, repr=False)

    def row(self, target_cell: int) -> int:
        hit = np.flatnonzero(self.targets == int(target_cell))
        if hit.size == 0:
            raise InvalidSettingError(f"target cell {target_cell} is not in this solution", hint="solve for it")
        return int(hit[0])

    def q(self, rows: np.ndarray | None = None) -> np.ndarray:
        """``float64[K, N, 4]`` Q* of the solution's targets (or of ``rows`` of them), exactly from V*."""
        rows = np.arange(self.targets.size) if rows is None else np.asarray(rows, np.int64)
        tab = self.tab
        r, reached = tab.rewards(self.reward, tab.states(self.targets[rows]))
        return r + self.gamma * ~reached * self.values[rows][np.arange(rows.size)[:, None, None], tab.next[None]]

    def greedy(self) -> np.ndarray:
        """``int64[K, N]`` the greedy move of Q* (the first of equal values, in action order)."""
        k, out = chunk_size(self.tab.n), np.empty(self.values.shape, np.int64)  # filled in place: no second copy
        for i in range(0, self.targets.size, k):
            out[i : i + k] = self.q(np.arange(i, min(i + k, self.targets.size))).argmax(-1)
        return out

    def meta(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "dataset": self.name,
            "version": self.version,
            "reward": self.reward,
            "gamma": self.gamma,
            "targets": int(self.targets.size),
            "states": int(self.values.shape[1]),
            "sweeps": self.sweeps,
            "residual": self.residual,
            "seconds": self.seconds,
            "tol": TOL,
        }


def solve(
    tab: TabularMDP,
    reward: str = "geodesic",
    gamma: float = GAMMA,
    targets: np.ndarray | None = None,
    *,
    name: str = "",
    version: str = "",
    progress=None,
) -> Solution:
    """V* for ``targets`` (grid cells; default every free cell), chunk by chunk (module docstring). ``progress``, if
    given, is called with the number of targets done."""
    check_reward(reward)
    gamma = check_gamma(gamma)
    cells = tab.cells if targets is None else np.unique(np.asarray(targets, np.int64))
    t_states = tab.states(cells)
    check_size(cells.size, tab.n)
    check_memory(
        f"the exact solution of {name or tab.mdp.name}",
        solve_parts(cells.size, tab.n),
        hint="solve for fewer targets (targets=..., e.g. the evaluation pairs' targets) or a twin of coarser cells",
    )
    t0 = time.perf_counter()
    values = np.empty((cells.size, tab.n))
    sweeps, residual = 0, 0.0
    k = chunk_size(tab.n)
    for i in range(0, cells.size, k):
        r, reached = tab.rewards(reward, t_states[i : i + k])
        v, s, res = bellman_sweeps(r, reached, tab.next, gamma)
        values[i : i + k] = v
        sweeps, residual = max(sweeps, s), max(residual, res)
        if progress is not None:
            progress(min(i + k, cells.size))
    sol = Solution(name or tab.mdp.name, version, reward, gamma, cells, values, sweeps, residual, 0.0, tab)
    sol.seconds = time.perf_counter() - t0
    return sol


__all__ = [
    "CHUNK_BYTES",
    "GAMMA",
    "Solution",
    "TabularMDP",
    "TooLargeError",
    "bellman_sweeps",
    "expectation_sweeps",
    "check_size",
    "chunk_size",
    "solve",
]
