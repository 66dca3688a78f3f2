"""The paper's training pairs (Table VI) on our grids: one fixed (start, target) pair per training run.

The paper gives each pair in its own coordinates and never states the frame. What the numbers fit:

* **Indoor** (cubicle, meeting): *cell offsets from the grid centre*, ``ix = nx // 2 + a``, ``iy = ny // 2 + b``.
  The cubicle's [-8, -9] -> [17, 8] then lands on (13, 0) -> (38, 17) of its 42 x 18 grid, both rows at the
  grid's edges, exactly the range -9..8 of the offsets; the meeting room's [-20, -22] falls 1-2 cells off its
  38 x 40 grid and is clamped onto it.
* **City quadrants**: *metres in the scene frame* centred on the downtown box (the quadrant frame of the paper's
  Tables III and IV), ``ix = round((x - x0) / cell)``. The paper's frame is larger than its own lon/lat box (its
  Dallas pairs reach y = 360 m in a 0.5 km box), so a coordinate outside the quadrant's grid is clamped onto its edge.

Then each end is **snapped** to the nearest free cell (Euclidean, in cells) of the largest 4-connected free region
of the twin, so both ends are free and connected; :class:`ResolvedPair` records how far each moved. Scenes the
paper has no pair for (synthetic tables, Sionna scenes, a user's room) get a stand-in: the free cell of the largest
region nearest the grid's (0, 0) corner, to the cell of that region farthest from it by breadth-first steps.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError
from dtradar_data.core.grid import Grid
from dtradar_rl.task.grid_mdp import GridMDP


class PairError(DtradarError, ValueError):
    """A training pair that cannot be placed on a twin (off the grid, blocked, or not connected)."""


@dataclass(frozen=True)
class PaperPair:
    """One row of the paper's Table VI: the pair in the paper's coordinates and what the paper reached."""

    scene: str
    start: tuple[float, float]
    target: tuple[float, float]
    #: ``"cells"`` (offsets from the grid centre) or ``"metres"`` (scene frame)
    frame: str
    min_steps: int
    episode: int


def _row(scene, start, target, frame, steps, episode) -> tuple[str, PaperPair]:
    return scene, PaperPair(scene, start, target, frame, steps, episode)


#: Paper Table VI, start -> target, minimum steps reached in training and the episode it was reached in.
TABLE_VI: dict[str, PaperPair] = dict(
    [
        _row("cubicle", (-8, -9), (17, 8), "cells", 45, 13),
        _row("meeting", (-20, -22), (17, 17), "cells", 78, 389),
        _row("dallas-q1", (-275, -328), (-175, -1), "metres", 808, 19),
        _row("dallas-q2", (-160, 0), (-200, 360), "metres", 1475, 32),
        _row("dallas-q3", (200, 0), (0, 160), "metres", 416, 37),
        _row("dallas-q4", (75, -328), (0, -160), "metres", 307, 25),
        _row("houston-q1", (-570, -473), (-1, -161), "metres", 2245, 14),
        _row("houston-q2", (-297, 0), (-1, 140), "metres", 1668, 67),
        _row("houston-q3", (460, 0), (0, 300), "metres", 2246, 55),
        _row("houston-q4", (-462, -301), (200, -1), "metres", 6431, 72),
    ]
)

#: With a fixed pair, the episode cap is this many times the pair's breadth-first shortest path (the paper's
#: episodes run until the target; this is only a safety net against a policy stuck against a wall forever).
CAP_FACTOR = 10


@dataclass(frozen=True)
class ResolvedPair:
    """A pair placed on one twin: grid cells ``(ix, iy)``, where they came from and the shortest path between."""

    start: tuple[int, int]
    target: tuple[int, int]
    source: str  # "table6", "given" or "stand-in"
    raw_start: tuple[int, int]  # before snapping (after clamping onto the grid)
    raw_target: tuple[int, int]
    snapped_cells: tuple[float, float]  # how far each end moved when snapped (cells)
    shortest: int  # breadth-first steps on this twin
    cap: int  # episode safety cap: CAP_FACTOR x shortest, at least the MDP's default limit

    def cells(self, nx: int) -> tuple[int, int]:
        """``(start, target)`` as cell indices ``iy * nx + ix``."""
        return self.start[1] * nx + self.start[0], self.target[1] * nx + self.target[0]

    def to_dict(self) -> dict:
        return asdict(self)


def paper_pair(scene: str) -> PaperPair | None:
    """The scene's Table VI row, or ``None`` when the paper trained no pair on it."""
    return TABLE_VI.get(scene)


def to_grid(pair: PaperPair, grid: Grid) -> tuple[tuple[int, int], tuple[int, int]]:
    """The pair's two ends as grid cells ``(ix, iy)``, clamped onto the grid (see the module docstring)."""

    def one(p):
        if pair.frame == "cells":
            ix, iy = grid.nx // 2 + int(p[0]), grid.ny // 2 + int(p[1])
        else:
            ix = int(round((p[0] - grid.x0_m) / grid.cell_m))
            iy = int(round((p[1] - grid.y0_m) / grid.cell_m))
        return int(np.clip(ix, 0, grid.nx - 1)), int(np.clip(iy, 0, grid.ny - 1))

    return one(pair.start), one(pair.target)


def largest_region(mdp: GridMDP) -> np.ndarray:
    """``bool[H*W]``: the cells of the largest 4-connected free region."""
    comp = mdp.component
    if not (comp >= 0).any():
        raise PairError(f"{mdp.name}: the grid has no free cell", hint="check the dataset's blocked mask")
    return comp == np.bincount(comp[comp >= 0]).argmax()


def snap(mdp: GridMDP, ix: int, iy: int, region: np.ndarray | None = None) -> tuple[tuple[int, int], float]:
    """The cell of ``region`` (default: the largest free region) nearest ``(ix, iy)``, and the distance moved."""
    region = largest_region(mdp) if region is None else region
    cells = np.flatnonzero(region)
    cx, cy = mdp.xy(cells)
    d2 = (cx - ix) ** 2 + (cy - iy) ** 2
    k = int(np.argmin(d2))  # first minimum: ties go to the lower row-major index, so snapping is deterministic
    return (int(cx[k]), int(cy[k])), float(np.sqrt(d2[k]))


def stand_in(mdp: GridMDP) -> tuple[tuple[int, int], tuple[int, int]]:
    """A pair across the grid for scenes without a Table VI row (see the module docstring)."""
    start, _ = snap(mdp, 0, 0)
    d = mdp.bfs_distances(mdp.cell(*start))
    far = int(np.argmax(d))
    return start, tuple(int(v) for v in mdp.xy(far))


def resolve(
    mdp: GridMDP, grid: Grid, scene: str, start: tuple[int, int] | None = None, target: tuple[int, int] | None = None
) -> ResolvedPair:
    """The training pair of ``scene`` on a twin: ``start``/``target`` cells when given (they must be free and
    connected: a user's choice is not moved), else the Table VI pair transformed and snapped, else a stand-in."""
    region = largest_region(mdp)
    if (start is None) != (target is None):
        raise PairError("give both --start and --target (cells ix iy), or neither")
    if start is not None:
        for name, (ix, iy) in (("--start", start), ("--target", target)):
            if not (0 <= ix < mdp.nx and 0 <= iy < mdp.ny):
                raise PairError(f"{name} {ix} {iy} is outside the {mdp.nx} x {mdp.ny} grid")
            if mdp.blocked[iy, ix]:
                raise PairError(
                    f"{name} {ix} {iy} is a blocked cell of {mdp.name}",
                    hint="pick a free cell (the twin's coverage map shows obstacles)",
                )
        s, t = tuple(start), tuple(target)
        if not mdp.connected(mdp.cell(*s), mdp.cell(*t)):
            raise PairError(f"--start {s} and --target {t} are not connected on {mdp.name}")
        source, raw, moved = "given", (s, t), (0.0, 0.0)
    else:
        row = paper_pair(scene)
        if row is not None:
            raw = to_grid(row, grid)
            (s, ds), (t, dt) = snap(mdp, *raw[0], region), snap(mdp, *raw[1], region)
            source, moved = "table6", (ds, dt)
        else:
            s, t = stand_in(mdp)
            source, raw, moved = "stand-in", (s, t), (0.0, 0.0)
    if s == t:
        raise PairError(f"start and target are the same cell {s} on {mdp.name}")
    shortest = int(mdp.bfs_distances(mdp.cell(*t))[mdp.cell(*s)])
    return ResolvedPair(s, t, source, raw[0], raw[1], moved, shortest, max(CAP_FACTOR * shortest, mdp.max_steps))


def training_pair(cfg, ds: Dataset) -> ResolvedPair | None:
    """The fixed (start, target) pair of a run's config (``fixed_pair``, ``scene``, ``start``, ``target``: a
    :class:`~dtradar_rl.train.config.DQNConfig`) on ``ds``, or ``None`` when it trains on random pairs."""
    if not cfg.fixed_pair:
        return None
    return resolve(GridMDP.from_dataset(ds), ds.grid_info, cfg.scene, cfg.start, cfg.target)


__all__ = [
    "TABLE_VI",
    "CAP_FACTOR",
    "training_pair",
    "PaperPair",
    "ResolvedPair",
    "PairError",
    "paper_pair",
    "to_grid",
    "snap",
    "stand_in",
    "resolve",
    "largest_region",
]
