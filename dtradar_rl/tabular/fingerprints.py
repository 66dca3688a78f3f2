"""Where the robot believes it is: the blueprint cell whose radio fingerprint is nearest to what it senses.

A tabular agent indexes its table by a cell, but a robot senses radio features, not its cell. As the classical
planner does (:class:`~dtradar_rl.agents.planner.FingerprintPlanner`), the believed cell is the free blueprint cell
with radio features whose 8 z-scored radio features (AoA, AoD, coefficient, delay, phase; the training twin's
normaliser) are nearest, in Euclidean distance, to the features sensed on the robot's cell. Without measurement noise
this is a fixed map ``true cell -> believed cell`` per twin (:func:`localisation`), so a table policy composed with it
is again a table, which :mod:`dtradar_rl.tabular.evaluation` evaluates exactly. A free cell without any propagation
path senses nothing (all features missing, 0 after normalisation) and is matched like any other fingerprint. On a
twin with several transmitters a fingerprint holds every transmitter's 8 features (transmitter 0's first, as the
observation orders them; 0 where one has no path), and a cell has radio features when any transmitter reaches it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from dtradar_data.core.dataset import Dataset
from dtradar_rl.task.grid_mdp import ACTION_DELTAS, GridMDP
from dtradar_rl.task.moving_masks import background
from dtradar_rl.task.observations import RADIO_FEATURES, Normalizer, check_transmitters, radio_columns

#: The normalised columns a fingerprint holds (the radio features, no position) with one transmitter; with several,
#: :func:`fingerprint_columns`.
FINGERPRINT_COLUMNS: tuple[str, ...] = RADIO_FEATURES


def fingerprint_columns(normalizer: Normalizer) -> tuple[str, ...]:
    """The normalised columns of a fingerprint: every transmitter's radio features, transmitter 0's first."""
    return tuple(c for k in range(normalizer.transmitters) for c in radio_columns(k))


def fingerprints(ds: Dataset, normalizer: Normalizer) -> tuple[np.ndarray, np.ndarray]:
    """``(float32[H*W, 8K] features, bool[H*W] has_radio)``: every cell's z-scored radio features of its ``K``
    transmitters (0 where missing) and whether the cell is free with every feature of at least one present."""
    ds = background(ds)
    check_transmitters(normalizer, ds)
    names = fingerprint_columns(normalizer)
    cols = [normalizer.columns.index(c) for c in names]
    raw = ds.grid(list(normalizer.columns)).reshape(-1, len(normalizer.columns)).astype(np.float64)
    free = ~np.asarray(ds.blocked, bool).ravel()
    per_tx = np.isfinite(raw[:, cols]).reshape(len(raw), -1, len(RADIO_FEATURES)).all(2)  # [cells, K]
    has_radio = free & per_tx.any(1)
    return normalizer.apply(raw)[:, cols], has_radio


def localisation(blueprint: Dataset, ds: Dataset | None = None, normalizer: Normalizer | None = None) -> np.ndarray:
    """``int64[H*W]``: the believed blueprint cell of every cell of ``ds`` (default: the blueprint itself), by the
    nearest fingerprint among the blueprint's free cells with radio features; -1 for the cells blocked in ``ds``.
    ``normalizer`` defaults to the blueprint's (what a table trained on it would carry)."""
    normalizer = normalizer or Normalizer.fit(blueprint)
    ds = blueprint if ds is None else ds
    ref, ref_radio = fingerprints(blueprint, normalizer)
    seen, _ = fingerprints(ds, normalizer)
    if ref.shape != seen.shape:
        raise ValueError(f"{ds.name} has another grid than {blueprint.name}: {seen.shape} vs {ref.shape}")
    cells = np.flatnonzero(ref_radio)
    free = ~np.asarray(background(ds).blocked, bool).ravel()
    out = np.full(free.size, -1, np.int64)
    if cells.size:
        _, idx = cKDTree(ref[cells].astype(np.float64)).query(seen[free].astype(np.float64))
        out[free] = cells[idx]
    return out


@dataclass(frozen=True)
class Ambiguity:
    """How well the fingerprints tell cells apart on one twin (:func:`ambiguity`)."""

    free_cells: int
    #: free cells without radio features (they all sense the same nothing)
    no_radio: int
    #: free cells with radio features whose fingerprint equals another cell's exactly
    shared: int
    #: free cells believed to be somewhere else (the localisation map is not the identity there)
    mislocalised: int
    #: mean Manhattan distance, in cells, between the true and the believed cell, over the mislocalised cells
    mean_error_cells: float

    def to_dict(self) -> dict:
        return self.__dict__.copy()


def ambiguity(blueprint: Dataset, ds: Dataset | None = None, normalizer: Normalizer | None = None) -> Ambiguity:
    """How many cells share a fingerprint and how many ``ds`` (default the blueprint) localises elsewhere."""
    normalizer = normalizer or Normalizer.fit(blueprint)
    ds = blueprint if ds is None else ds
    fp, radio = fingerprints(blueprint, normalizer)
    _, counts = np.unique(fp[radio], axis=0, return_counts=True)
    loc = localisation(blueprint, ds, normalizer)
    mdp = GridMDP.from_dataset(background(ds))
    free = np.flatnonzero(mdp.free)
    wrong = free[loc[free] != free]
    (x0, y0), (x1, y1) = mdp.xy(wrong), mdp.xy(loc[wrong])
    err = np.abs(x0 - x1) + np.abs(y0 - y1)
    _, ds_radio = fingerprints(ds, normalizer)
    return Ambiguity(
        free_cells=int(free.size),
        no_radio=int((mdp.free & ~ds_radio).sum()),
        shared=int(counts[counts > 1].sum()),
        mislocalised=int(wrong.size),
        mean_error_cells=float(err.mean()) if err.size else 0.0,
    )


class Tracker:
    """Where a moving robot believes it is: fingerprints searched near where its own moves say it went.

    On a twin whose objects changed, the radio features near a new object are not the blueprint's, and the nearest
    fingerprint over the whole blueprint can be far away (:func:`ambiguity` counts them). A robot also knows which
    move it made and whether it bumped (the move did not change its cell), so it can carry its belief along: the
    **predicted** cell is the believed cell moved by that move (or kept, after a bump), and the new belief is the
    nearest fingerprint among the blueprint cells with radio within ``window`` moves (Manhattan) of the prediction.
    ``window=0`` is dead reckoning from the first fingerprint; ``window >= 1`` lets the fingerprints correct a wrong
    start. Where nothing with radio lies in the window, or the robot's cell senses nothing, the prediction is kept;
    where the prediction is not a free blueprint cell (a belief already wrong), the global fingerprint is used.
    The first belief of an episode is the global nearest fingerprint (:func:`localisation`)."""

    def __init__(self, blueprint: Dataset, ds: Dataset, window: int = 1, normalizer: Normalizer | None = None):
        if not (isinstance(window, (int, np.integer)) and window >= 0):
            raise ValueError(f"window must be an int >= 0, got {window!r}")
        normalizer = normalizer or Normalizer.fit(blueprint)
        self.window = int(window)
        self.ref, self.ref_radio = fingerprints(blueprint, normalizer)
        self.seen, self.seen_radio = fingerprints(ds, normalizer)
        self.glob = localisation(blueprint, ds, normalizer)
        self.mdp = GridMDP.from_dataset(background(blueprint))
        self.free = np.asarray(self.mdp.free, bool)
        w = self.window
        self.offsets = np.array(
            [(dx, dy) for dx in range(-w, w + 1) for dy in range(-w, w + 1) if abs(dx) + abs(dy) <= w], np.int64
        )

    def start(self, cells: np.ndarray) -> np.ndarray:
        """The first belief (a blueprint grid cell) of robots on the twin's grid ``cells``."""
        return self.glob[np.asarray(cells, np.int64)]

    def step(self, believed: np.ndarray, moves: np.ndarray, moved: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """The belief after each robot made ``moves`` from ``believed``; ``moved`` says which changed cell, ``cells``
        are the twin cells the robots are on now (only their sensed features are read)."""
        nx, ny = self.mdp.nx, self.mdp.ny
        iy, ix = np.divmod(np.asarray(believed, np.int64), nx)
        d = np.where(np.asarray(moved, bool)[:, None], ACTION_DELTAS[np.asarray(moves, np.int64)], 0)
        px, py = ix + d[:, 0], iy + d[:, 1]
        inside = (px >= 0) & (px < nx) & (py >= 0) & (py < ny)
        pred = np.where(inside, py * nx + px, 0)
        ok = inside & self.free[pred]
        cx, cy = px[:, None] + self.offsets[None, :, 0], py[:, None] + self.offsets[None, :, 1]
        cand = np.where((cx >= 0) & (cx < nx) & (cy >= 0) & (cy < ny), cy * nx + cx, -1)
        valid = (cand >= 0) & self.ref_radio[cand.clip(0)]
        cells = np.asarray(cells, np.int64)
        dist = ((self.ref[cand.clip(0)] - self.seen[cells][:, None]) ** 2).sum(-1)
        best = cand[np.arange(cand.shape[0]), np.where(valid, dist, np.inf).argmin(1)]
        use_fp = valid.any(1) & self.seen_radio[cells]
        out = np.where(use_fp, best, pred)
        return np.where(ok, out, self.glob[cells])


__all__ = [
    "FINGERPRINT_COLUMNS",
    "Ambiguity",
    "Tracker",
    "ambiguity",
    "fingerprint_columns",
    "fingerprints",
    "localisation",
]
