"""Do two traces of one grid agree? The strongest-path rule the benchmarks and the differential-build test share.

A cell *agrees* when both traces find the same strongest path (the same interaction sequence where both recorded
it, delay within 0.1 ns) with all four angles within 1° (azimuths ignored where the zenith is within 1° of a pole).
Cells without a path in both traces agree. Ray sampling makes even two full traces of one scene differ a little
(``make bench-rt`` measures how much), so agreement is a rate, never an equality.
"""

from __future__ import annotations

import numpy as np

from dtradar_data.core.dataset import Dataset

TAU_TOL_S = 1e-10
ANGLE_TOL_RAD = np.deg2rad(1.0)
ANGLE_KEYS = ("aod_zen_rad", "aod_az_rad", "aoa_zen_rad", "aoa_az_rad")


def strongest_of(ds: Dataset) -> dict[str, np.ndarray]:
    """Per cell (row-major, all cells): ``has`` a path, its ``inter``-action letters ('' where not recorded), delay
    and angles of the strongest path (NaN where none). Interactions come from the per-path table when stored."""
    table = ds.table
    n = table.num_rows
    tau = np.array(table.column("tau_s").to_numpy(zero_copy_only=False), dtype=float)
    out = {"has": ~np.isnan(tau), "inter": np.full(n, "", dtype=object), "tau_s": tau}
    for k in ANGLE_KEYS:
        out[k] = np.array(table.column(k).to_numpy(zero_copy_only=False), dtype=float)
    paths = ds.paths_table
    if paths is not None and paths.num_rows:
        first = paths.column("path").to_numpy() == 0
        ix, iy = paths.column("ix").to_numpy()[first], paths.column("iy").to_numpy()[first]
        nx = int(ds.shape[1])
        out["inter"][iy * nx + ix] = np.asarray(paths.column("interactions").to_pylist(), dtype=object)[first]
    return out


def agreement(ref: dict[str, np.ndarray], got: dict[str, np.ndarray]) -> np.ndarray:
    """Per-cell bool: the two traces' strongest paths agree (see the module docstring)."""
    both_none = ~ref["has"] & ~got["has"]
    recorded = (ref["inter"] != "") & (got["inter"] != "")
    same = (
        ref["has"]
        & got["has"]
        & (~recorded | (ref["inter"] == got["inter"]))
        & (np.abs(ref["tau_s"] - got["tau_s"]) < TAU_TOL_S)
    )

    def close(a, b, wrap):
        d = np.abs(a - b)
        return np.minimum(d, 2 * np.pi - d) < ANGLE_TOL_RAD if wrap else d < ANGLE_TOL_RAD

    with np.errstate(invalid="ignore"):
        for zen, az in (("aod_zen_rad", "aod_az_rad"), ("aoa_zen_rad", "aoa_az_rad")):
            pole = (ref[zen] < ANGLE_TOL_RAD) | (ref[zen] > np.pi - ANGLE_TOL_RAD)
            same &= close(ref[zen], got[zen], False) & (pole | close(ref[az], got[az], True))
    return both_none | same


def compare(ref: Dataset, got: Dataset) -> dict[str, np.ndarray]:
    """Per cell of two traces of one grid: ``agree`` (strongest path), ``gain_diff_db`` (absolute difference of the
    total path gain; NaN where either has none) and ``free`` (free in both)."""
    if ref.shape != got.shape:
        raise ValueError(f"cannot compare grids of shapes {ref.shape} and {got.shape}")
    free = ~ref.blocked.ravel() & ~got.blocked.ravel()

    def gain(ds):
        return np.array(ds.table.column("path_gain_db").to_numpy(zero_copy_only=False), dtype=float)

    return {
        "agree": agreement(strongest_of(ref), strongest_of(got)),
        "gain_diff_db": np.abs(gain(ref) - gain(got)),
        "free": free,
    }


def summarize(c: dict[str, np.ndarray], where: np.ndarray | None = None) -> dict[str, float]:
    """A :func:`compare` result over its free cells (of ``where``): how many, the strongest-path agreement rate, and
    the median and 95th percentile of the absolute total-gain differences (NaN where there is nothing to count)."""
    sel = c["free"] if where is None else c["free"] & where
    g = c["gain_diff_db"][sel]
    g = g[~np.isnan(g)]
    return {
        "cells": int(sel.sum()),
        "agreement": float(c["agree"][sel].mean()) if sel.any() else float("nan"),
        "gain_median_db": float(np.median(g)) if g.size else float("nan"),
        "gain_p95_db": float(np.percentile(g, 95)) if g.size else float("nan"),
    }
