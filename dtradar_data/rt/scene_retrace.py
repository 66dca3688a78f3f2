"""Re-trace a dataset version from the scene it stores, with plain Sionna, and compare each cell's strongest path.

This checks that the stored scene (``ds.scene_xml``, :mod:`dtradar_data.geometry.scene_files`) is the one the tables
were traced from: :func:`retrace_strongest` opens it with ``sionna.rt.load_scene`` alone (no dtradar tracer, no
patched solver), adds the version's arrays and transmitters from its ``meta.json`` and traces its free cells with
Sionna's own ``PathSolver`` at the version's settings; :func:`strongest_path_agreement` counts the cells whose
strongest path is the stored one (its delay, its power at the reference ports and whether it is the line of sight).

Sionna's own solver shares a hash table between the receivers of a call (see :mod:`.tracer`): it may drop a weak
path the batch-independent build kept, so receivers go in small calls (``batch``) and the count allows for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dtradar_data.core.schema import tx_column
from dtradar_data.rt.tracer import _import_sionna

#: A cell's strongest path is "the same" when its delay is within this (1 cm of travel) ...
TAU_TOL_S = 3e-11
#: ... its power at the reference ports within this, and line of sight (or not) in both.
POWER_TOL_DB = 0.1


@dataclass(frozen=True)
class Strongest:
    """Per free cell (row-major) and transmitter ``k`` (axis 0): the number of paths, and of the strongest path (by
    power averaged over all port pairs) its delay, its power at the reference ports (RX 0, TX 0; dB) and whether it
    is the line of sight; NaN / False where a cell has no path."""

    num_paths: np.ndarray  # int [K, N]
    tau_s: np.ndarray  # float [K, N]
    power_db: np.ndarray  # float [K, N]
    los: np.ndarray  # bool [K, N]


def stored_strongest(ds) -> Strongest:
    """The strongest paths a static version stores, for its free cells in row-major order."""
    free = ~ds.table.column("blocked").to_numpy(zero_copy_only=False)

    def col(name: str, k: int) -> np.ndarray:
        c = ds.table.column(tx_column(name, k)).cast("float64").fill_null(np.nan)
        return c.to_numpy(zero_copy_only=False)[free]

    k_all = range(ds.transmitters)
    a = [np.hypot(col("a_re", k), col("a_im", k)) for k in k_all]
    return Strongest(
        num_paths=np.stack([np.nan_to_num(col("num_paths", k)).astype(int) for k in k_all]),
        tau_s=np.stack([col("tau_s", k) for k in k_all]),
        power_db=np.stack([20 * np.log10(x) for x in a]),
        los=np.stack([col("los", k) == 1 for k in k_all]),
    )


def receiver_points(ds) -> np.ndarray:
    """The free cells' centres at the version's receiver height, ``[N, 3]`` row-major (scenes without terrain: the
    receivers of a version on an external XML with a ground mesh stand on it, which ``meta.json`` does not record)."""
    t = ds.table
    free = ~t.column("blocked").to_numpy(zero_copy_only=False)
    x, y = (t.column(c).to_numpy()[free] for c in ("x_m", "y_m"))
    return np.stack([x, y, np.full_like(x, float(ds.meta["rx_height_m"]))], axis=1)


def retrace_strongest(ds, *, batch: int = 16, threads: int = 1) -> Strongest:
    """Open ``ds.scene_xml`` with plain ``sionna.rt.load_scene``, set it up as ``meta.json`` says (carrier, arrays,
    transmitters) and trace the free cells with ``sionna.rt.PathSolver`` at the version's settings, ``batch``
    receivers per call on ``threads`` Dr.Jit threads (the build's one thread by default: the weak paths depend on
    it). Returns the strongest path of each cell, as :func:`stored_strongest` gives the stored ones."""
    _, rt = _import_sionna("cpu", cpu_only=True)  # configures LLVM and the variant the builds use
    import drjit as dr

    meta = ds.meta
    scene = rt.load_scene(str(ds.scene_xml))
    scene.frequency = float(meta["rt"]["frequency_hz"])
    tx0 = meta["transmitter"]
    scene.tx_array = rt.PlanarArray(
        num_rows=tx0["num_rows"], num_cols=tx0["num_cols"], pattern=tx0["pattern"], polarization=tx0["polarization"]
    )
    scene.rx_array = rt.PlanarArray(
        num_rows=1, num_cols=1, pattern=meta["rt"]["rx_pattern"], polarization=meta["rt"]["rx_polarization"]
    )
    transmitters = meta.get("transmitters") or [tx0]
    for k, t in enumerate(transmitters):
        scene.add(rt.Transmitter("tx" if k == 0 else f"tx{k}", position=list(t["position_m"]), **_pose(t)))
    kwargs = _solver_kwargs(meta["rt"])
    points = receiver_points(ds)
    parts, names = [], []
    previous = dr.thread_count()
    dr.set_thread_count(threads)
    try:
        for s in range(0, len(points), batch):
            for name in names:
                scene.remove(name)
            names = [f"rx{i}" for i in range(s, min(s + batch, len(points)))]
            for name, p in zip(names, points[s : s + batch]):
                scene.add(rt.Receiver(name, position=[float(v) for v in p]))
            parts.append(_strongest(rt.PathSolver()(scene, **kwargs), len(transmitters)))
    finally:
        dr.set_thread_count(previous)
    return Strongest(*(np.concatenate([getattr(p, f) for p in parts], axis=1) for f in Strongest.__dataclass_fields__))


def _pose(t: dict) -> dict:
    """Sionna's Transmitter keywords of a recorded transmitter: an exact orientation wins over the look-at point."""
    pose = {"power_dbm": t.get("power_dbm", 0.0)}
    if t.get("orientation_deg") is not None:
        return {**pose, "orientation": [math.radians(v) for v in t["orientation_deg"]]}
    return {**pose, **({"look_at": list(t["look_at_m"])} if t.get("look_at_m") is not None else {})}


def _solver_kwargs(rt: dict) -> dict:
    """``PathSolver`` keywords from a version's recorded RT settings (Sionna's own names)."""
    keys = ("max_depth", "max_num_paths_per_src", "samples_per_src", "synthetic_array", "los")
    keys += ("specular_reflection", "diffuse_reflection", "refraction", "diffraction", "seed")
    return {k: rt[k] for k in keys if k in rt}


def _strongest(paths, num_tx: int) -> Strongest:
    """The strongest path of each receiver of one call (synthetic arrays: geometry per transmitter, not per port)."""
    a = np.asarray(paths.a[0], np.float64) + 1j * np.asarray(paths.a[1], np.float64)  # [rx, rx ports, tx, tx ports, P]
    valid = np.asarray(paths.valid, bool)  # [rx, tx, P]
    tau = np.asarray(paths.tau, np.float64)
    depth = (np.asarray(paths.interactions) != 0).sum(axis=0)  # [rx, tx, P]
    if valid.shape[-1] == 0:  # no receiver of the call has a path: Sionna gives P = 0; one invalid path instead

        def one(x):
            return np.zeros((*x.shape[:-1], 1), x.dtype)

        a, valid, tau, depth = one(a), one(valid), one(tau), one(depth)
    out = {f: [] for f in Strongest.__dataclass_fields__}
    rows = np.arange(len(valid))
    for k in range(num_tx):
        gain = np.where(valid[:, k], np.mean(np.abs(a[:, :, k]) ** 2, axis=(1, 2)), -1.0)
        has = valid[:, k].any(axis=1)
        best = np.argmax(gain, axis=1)
        with np.errstate(divide="ignore"):
            power = 20 * np.log10(np.abs(a[rows, 0, k, 0, best]))
        out["num_paths"].append(valid[:, k].sum(axis=1))
        out["tau_s"].append(np.where(has, tau[rows, k, best], np.nan))
        out["power_db"].append(np.where(has, power, np.nan))
        out["los"].append(has & (depth[rows, k, best] == 0))
    return Strongest(*(np.stack(out[f]) for f in Strongest.__dataclass_fields__))


def strongest_path_agreement(stored: Strongest, retraced: Strongest) -> dict:
    """How many cells (of every transmitter) have the same strongest path in both: both without a path, or both
    with one whose delay, reference-port power and line of sight agree (:data:`TAU_TOL_S`, :data:`POWER_TOL_DB`)."""
    both = (stored.num_paths > 0) & (retraced.num_paths > 0)
    neither = (stored.num_paths == 0) & (retraced.num_paths == 0)
    with np.errstate(invalid="ignore"):
        d_tau = np.abs(stored.tau_s - retraced.tau_s)
        d_db = np.abs(stored.power_db - retraced.power_db)
        same = neither | (both & (d_tau <= TAU_TOL_S) & (d_db <= POWER_TOL_DB) & (stored.los == retraced.los))
    cells = int(same.size)
    return {
        "cells": cells,
        "same_strongest_path": int(same.sum()),
        "fraction": float(same.sum()) / cells if cells else 1.0,
        "cells_with_paths": int((stored.num_paths > 0).sum()),
        "same_num_paths": int((stored.num_paths == retraced.num_paths).sum()),
        "max_delay_diff_s": float(np.nanmax(np.where(both, d_tau, np.nan), initial=0.0)),
        "max_power_diff_db": float(np.nanmax(np.where(both, d_db, np.nan), initial=0.0)),
        "tolerances": {"delay_s": TAU_TOL_S, "power_db": POWER_TOL_DB},
    }
