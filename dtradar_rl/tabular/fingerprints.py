"""Where the robot believes it is: the blueprint cell whose radio fingerprint is nearest to what it senses.

A tabular agent indexes its table by a cell, but a robot senses radio features, not its cell. As the classical
planner does (:class:`~dtradar_rl.agents.planner.FingerprintPlanner`), the believed cell is the free blueprint cell
with radio features whose 8 z-scored radio features (AoA, AoD, coefficient, delay, phase; the training twin's
normaliser) are nearest, in Euclidean distance, to the features sensed on the robot's cell. Without measurement noise
this is a fixed map ``true cell -> believed cell`` per twin (:func:`localisation`), so a table policy composed with it
is again a table, which :mod:`dtradar_rl.tabular.evaluation` evaluates exactly. A free cell without any propagation
path senses nothing (all features missing, 0 after normalisation) and is matched like any other fingerprint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from dtradar_data.core.dataset import Dataset
from dtradar_rl.task.mdp import GridMDP, background
from dtradar_rl.task.observations import RADIO_FEATURES, Normalizer

#: The normalised columns a fingerprint holds (the radio features, no position).
FINGERPRINT_COLUMNS: tuple[str, ...] = RADIO_FEATURES


def fingerprints(ds: Dataset, normalizer: Normalizer) -> tuple[np.ndarray, np.ndarray]:
    """``(float32[H*W, 8] features, bool[H*W] has_radio)``: every cell's z-scored radio features (0 where missing)
    and whether the cell is free with every feature present."""
    ds = background(ds)
    cols = [normalizer.columns.index(c) for c in FINGERPRINT_COLUMNS]
    raw = ds.grid(list(normalizer.columns)).reshape(-1, len(normalizer.columns)).astype(np.float64)
    free = ~np.asarray(ds.blocked, bool).ravel()
    has_radio = free & np.isfinite(raw[:, [normalizer.columns.index(c) for c in FINGERPRINT_COLUMNS]]).all(1)
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


__all__ = ["FINGERPRINT_COLUMNS", "Ambiguity", "ambiguity", "fingerprints", "localisation"]
