"""A per-cell table as a grid navigation MDP: cells, moves, connectivity, shortest paths, rewards, start/target pairs.

Everything here is plain numpy and framework-free; :mod:`dtradar_rl.envs.nav_env` (gymnasium) and
:mod:`dtradar_rl.envs.batched` (torch) are two front ends over the same :class:`GridMDP`.

Conventions
-----------
* A *cell index* is ``c = iy * nx + ix`` (row-major, the order of the per-cell table).
* Free cells are states. Actions are ``0: X-``, ``1: X+``, ``2: Y-``, ``3: Y+`` (one cell per step).
* A move into a blocked cell or off the grid is a **collision**: the robot stays where it was.
* Distances in rewards are in **cell units** (``dx = ix_target - ix``, ``dy = iy_target - iy``).

Rewards (chosen by name, :data:`REWARDS`)
-----------------------------------------
``paper``      exactly the paper's reward: ``-(dx² + dy²)`` after the move, ``+5000`` on reaching the target,
               ``-5000`` on a collision (the terms add).
``scaled``     the paper's three terms rescaled to order one: ``-(dx² + dy²) / (nx² + ny²)``, ``+1`` on reaching the
               target, ``-1`` on a collision. Same optimum as ``paper``, better conditioned for a neural network.
``euclidean``  potential-based shaping (Ng et al. 1999) with the straight-line distance ``d``: ``d(s) - d(s')``
               (cell units), ``+1`` on reaching the target, ``-1`` on a collision. Uses no map knowledge.
``geodesic``   potential-based shaping with the breadth-first (obstacle-aware) distance ``g`` on the training twin:
               ``g(s) - g(s')`` (+1 for a step along a shortest path, -1 for a step away), ``+1`` on reaching the
               target, ``-1`` on a collision. The twin is known while training, so this is a legitimate training
               signal; the policy itself still sees only its observation. Being potential-based it leaves the
               shortest-path objective unchanged, and it makes every step informative, so it trains fastest;
               it is the tuned default.
"""

from __future__ import annotations

import math
import numbers
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, InvalidCoordinatesError, InvalidSettingError, unknown_name

ACTIONS: tuple[str, ...] = ("X-", "X+", "Y-", "Y+")
#: ``(dx, dy)`` of each action, in cells.
ACTION_DELTAS = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], dtype=np.int64)

REWARDS: tuple[str, ...] = ("paper", "scaled", "euclidean", "geodesic")
PAPER_GOAL_BONUS = 5000.0
PAPER_COLLISION_PENALTY = 5000.0


class NoConnectedPairError(DtradarError, ValueError):
    """A grid with no two connected free cells: no (start, target) pair can be drawn."""


def check_reward(name: str) -> str:
    """Return ``name`` if it is a known reward, else raise :class:`UnknownNameError` with a suggestion."""
    if name not in REWARDS:
        raise unknown_name("reward", name, REWARDS)
    return name


def default_max_steps(nx: int, ny: int) -> int:
    """The documented episode step limit: ``4 · (nx + ny)`` (240 on the 42 × 18 cubicle grid).

    Twice the longest obstacle-free Manhattan path, with room for detours; episodes are *truncated* there.
    """
    return 4 * (nx + ny)


def check_max_steps(max_steps) -> int | None:
    """``max_steps`` as a positive int, or None for the default (None or 0); anything else (a negative or
    fractional number, NaN, a bool, a string) is an :class:`InvalidSettingError`."""
    if max_steps is None:
        return None
    whole = isinstance(max_steps, numbers.Integral) or (
        isinstance(max_steps, numbers.Real) and math.isfinite(max_steps) and float(max_steps).is_integer()
    )
    if isinstance(max_steps, (bool, np.bool_)) or not whole:
        raise InvalidSettingError(
            f"max_steps must be a whole number of steps, got {max_steps!r}",
            hint="pass a positive int, or None for the default 4 * (nx + ny)",
        )
    if int(max_steps) < 0:
        raise InvalidSettingError(
            f"max_steps must be > 0, got {max_steps}", hint="pass a positive int, or None for the default 4 * (nx + ny)"
        )
    return int(max_steps) or None


def reward_fn(name: str, *, d2_after, pot_before, pot_after, collision, reached, diag2: float):
    """The reward of one step, elementwise, for numpy arrays, torch tensors or Python scalars.

    ``d2_after``: squared straight-line distance to the target after the move (cell units²), used by
    ``paper``/``scaled``; ``pot_before``/``pot_after``: the shaping distance before/after the move (straight-line
    for ``euclidean``, breadth-first for ``geodesic``, see :func:`potential_kind`); ``collision``/``reached``:
    booleans (bools or 0/1 numbers); ``diag2 = nx² + ny²``.
    """
    collision = collision * 1.0
    reached = reached * 1.0
    if name == "paper":
        return -d2_after + PAPER_GOAL_BONUS * reached - PAPER_COLLISION_PENALTY * collision
    if name == "scaled":
        return -d2_after / diag2 + reached - collision
    if name in ("euclidean", "geodesic"):
        return (pot_before - pot_after) + reached - collision
    raise unknown_name("reward", name, REWARDS)


def potential_kind(name: str) -> str | None:
    """Which distance a reward shapes with: ``"euclidean"``, ``"geodesic"`` or ``None``."""
    return name if check_reward(name) in ("euclidean", "geodesic") else None


@dataclass
class GridMDP:
    """The navigation MDP of one dataset: which cells are free, how they connect, where moves lead.

    Build with :meth:`from_dataset` (or :meth:`from_blocked` for hand-made grids).
    """

    name: str
    blocked: np.ndarray  # bool[H, W]
    #: ``int64[H*W, 4]``: the cell each action leads to (the same cell on a collision).
    next_cell: np.ndarray = field(repr=False)
    #: ``bool[H*W, 4]``: whether each action collides.
    collides: np.ndarray = field(repr=False)
    #: ``int64[H*W]``: connected-component label of each free cell (4-neighbour), -1 for blocked cells.
    component: np.ndarray = field(repr=False)

    @classmethod
    def from_dataset(cls, ds: Dataset) -> GridMDP:
        return cls.from_blocked(np.asarray(ds.blocked, bool), name=ds.name)

    @classmethod
    def from_blocked(cls, blocked: np.ndarray, name: str = "grid") -> GridMDP:
        blocked = np.asarray(blocked, bool)
        if blocked.ndim != 2 or blocked.size == 0:
            raise InvalidCoordinatesError(f"blocked mask must be a non-empty 2-D array, got shape {blocked.shape}")
        h, w = blocked.shape
        iy, ix = np.divmod(np.arange(h * w), w)
        nx_ = ix[:, None] + ACTION_DELTAS[None, :, 0]
        ny_ = iy[:, None] + ACTION_DELTAS[None, :, 1]
        inside = (nx_ >= 0) & (nx_ < w) & (ny_ >= 0) & (ny_ < h)
        target = np.where(inside, ny_ * w + nx_, 0)
        collides = ~inside | blocked.ravel()[target]
        next_cell = np.where(collides, np.arange(h * w)[:, None], target)
        mdp = cls(
            name=name, blocked=blocked, next_cell=next_cell, collides=collides, component=np.full(h * w, -1, np.int64)
        )
        mdp.component = mdp._components()
        return mdp

    # -- shape helpers -------------------------------------------------------------------------------------------
    @property
    def nx(self) -> int:
        return self.blocked.shape[1]

    @property
    def ny(self) -> int:
        return self.blocked.shape[0]

    @property
    def num_cells(self) -> int:
        return self.blocked.size

    @property
    def free(self) -> np.ndarray:
        """``bool[H*W]``: free cells (the states)."""
        return ~self.blocked.ravel()

    @property
    def diag2(self) -> float:
        return float(self.nx**2 + self.ny**2)

    @property
    def max_steps(self) -> int:
        return default_max_steps(self.nx, self.ny)

    def cell(self, ix: int, iy: int) -> int:
        if not (0 <= ix < self.nx and 0 <= iy < self.ny):
            raise InvalidCoordinatesError(f"cell ({ix}, {iy}) is outside the {self.nx} x {self.ny} grid")
        return int(iy) * self.nx + int(ix)

    def xy(self, cell) -> tuple:
        """``(ix, iy)`` of cell index/indices."""
        iy, ix = np.divmod(cell, self.nx)
        return ix, iy

    # -- connectivity and shortest paths -------------------------------------------------------------------------
    def _components(self) -> np.ndarray:
        comp = np.full(self.num_cells, -1, np.int64)
        label = 0
        for c in np.flatnonzero(self.free):
            if comp[c] >= 0:
                continue
            comp[c] = label
            queue = deque([c])
            while queue:
                u = queue.popleft()
                for v in self.next_cell[u]:
                    if comp[v] < 0:
                        comp[v] = label
                        queue.append(v)
            label += 1
        return comp

    def connected(self, a: int, b: int) -> bool:
        return bool(self.component[a] >= 0 and self.component[a] == self.component[b])

    def pair_cells(self) -> np.ndarray:
        """Free cells that have at least one other free cell in their component (valid starts and targets)."""
        comp = self.component
        sizes = np.bincount(comp[comp >= 0]) if (comp >= 0).any() else np.zeros(0, np.int64)
        ok = (comp >= 0) & (sizes[np.maximum(comp, 0)] >= 2) if sizes.size else np.zeros_like(comp, bool)
        return np.flatnonzero(ok)

    def bfs_distances(self, target: int) -> np.ndarray:
        """``int64[H*W]`` breadth-first step count from every cell to ``target``; -1 where unreachable/blocked."""
        return self.bfs_distances_many(np.array([target]))[0]

    def bfs_distances_many(self, targets: np.ndarray) -> np.ndarray:
        """``int64[K, H*W]`` BFS distances to each of ``targets`` at once (frontier propagation, vectorised)."""
        targets = np.asarray(targets, np.int64).ravel()
        k, n = targets.size, self.num_cells
        dist = np.full((k, n), -1, np.int64)
        rows = np.arange(k)
        dist[rows, targets] = 0
        frontier = np.zeros((k, n), bool)
        frontier[rows, targets] = True
        # Moves are symmetric between free cells, so "distance to target" = "distance from target": a cell is
        # reached at step s when one of its neighbours (a gather, no scatter) was on the frontier at step s-1.
        free = self.free
        step = 0
        while frontier.any():
            step += 1
            reach = np.zeros((k, n), bool)
            for a in range(4):
                reach |= frontier[:, self.next_cell[:, a]]
            new = reach & free & (dist < 0)
            dist[new] = step
            frontier = new
        return dist

    def shortest_path(self, start: int, target: int) -> list[int] | None:
        """One breadth-first shortest path ``[start, ..., target]`` as cell indices, or ``None`` if unreachable."""
        d = self.bfs_distances(target)
        if d[start] < 0:
            return None
        path = [int(start)]
        while path[-1] != target:
            u = path[-1]
            path.append(int(min(self.next_cell[u], key=lambda v: d[v] if d[v] >= 0 else 1 << 60)))
        return path

    # -- pairs ---------------------------------------------------------------------------------------------------
    def sample_pairs(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``int64[n, 2]`` (start, target) cell pairs, connected and distinct.

        The target is uniform over free cells that have a connected partner, the start uniform over the other
        cells of the target's component (the same distribution as start-first sampling).
        """
        cells = self.pair_cells()
        if cells.size == 0:
            raise NoConnectedPairError(
                f"{self.name}: no two free cells are connected, so no (start, target) pair exists",
                hint="check the blocked mask of the dataset",
            )
        targets = rng.choice(cells, size=n)
        starts = np.empty(n, np.int64)
        for i, t in enumerate(targets):
            members = np.flatnonzero(self.component == self.component[t])
            members = members[members != t]
            starts[i] = rng.choice(members)
        return np.stack([starts, targets], 1)

    # -- stepping (numpy; the reference the batched torch env is tested against) --------------------------------
    def step(self, cell: int, action: int) -> tuple[int, bool]:
        """``(next cell, collided)`` for one move."""
        return int(self.next_cell[cell, action]), bool(self.collides[cell, action])

    def d2(self, cell, target):
        """Squared straight-line distance in cell units."""
        (x, y), (tx, ty) = self.xy(cell), self.xy(target)
        return (tx - x) ** 2 + (ty - y) ** 2
