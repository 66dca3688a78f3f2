"""Moving twins: every snapshot of a :class:`~dtradar_data.scenes.moving_scene.MovingScene` traced into one table.

``build --variant moving`` (:mod:`dtradar_data.pipeline.moving_build`) traces snapshot 0 in full, like a blueprint,
and each snapshot ``k >= 1`` **differentially from snapshot k-1**: the changed objects are the movers that moved
between the two (:meth:`MovingScene.changed_between`: each mover's old and new box), the cells re-traced are those the
differential rule selects around them (:func:`dtradar_data.pipeline.differential.retrace_mask`: occupancy changed,
within the re-trace radius, line of sight or strongest path's first leg passing near), and every other cell keeps
snapshot ``k-1``'s row and per-path rows. A cell far from every mover is therefore traced once, in snapshot 0, and
carried through time. A differential snapshot's cells are traced in this process and in helper processes at once
(:mod:`dtradar_data.pipeline.trace_helpers`, one per further core; batch-independent tracing only), joined in
row-major order: the same rows as in one process.

Each finished snapshot is kept in the build's work folder (``snapshot_<k>.cells.parquet``, ``.paths.parquet`` and
``.json``, the JSON written last: a snapshot is done when its JSON exists), so an interrupted build restarts at the
first missing snapshot; snapshot 0's own trace batches are kept too (``snapshot_00000/``), as a static build's are.

:func:`moving_tables` joins the snapshots into the moving-twin table (:mod:`dtradar_data.core.dataset`): the
static columns, ``t = k`` and ``mover`` (the cells a mover covers at ``k``, by the same occupancy rule that makes
``blocked``: :func:`mover_mask`), rows sorted by ``(t, iy, ix)``; the per-path table gets ``t`` too.
:func:`render_gif` draws the path gain per cell over time with the movers' cells marked (the card's animation).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm.auto import tqdm

from dtradar_data.core import layout as P
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.core.schema import MOVING_CELL_SCHEMA, MOVING_PATH_SCHEMA
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import differential
from dtradar_data.pipeline.trace_helpers import TraceHelpers, helper_count
from dtradar_data.rt.tracer import RayTracer

#: The animation stored beside the card of a moving twin.
GIF_FILE = P.MOVING_GIF_FILE
#: At most this many frames in the animation (snapshots evenly picked): a 500-snapshot city twin stays a small file.
GIF_MAX_FRAMES = 120

#: ``full_trace(spec, work_dir) -> (cells, paths, blocked, tracer)``: how snapshot 0 is traced (a static
#: build's :func:`~dtradar_data.pipeline.tracing.trace_grid`, resumable by batch in ``work_dir``).
FullTrace = Callable[[Any, Path], tuple]


@dataclass(frozen=True)
class Snapshot:
    """One traced snapshot: its static-schema tables and how it was made (``record``: ``t``, ``mode`` ``"full"``
    or ``"differential"``, ``retraced_cells``, ``free_cells``, ``reasons``, ``movers_moved``, ``seconds``)."""

    k: int
    cells: pa.Table
    paths: pa.Table | None
    record: dict[str, Any]


# ------------------------------------------------------------------------------------------- occupancy
def mover_mask(moving, k: int) -> np.ndarray:
    """``bool[ny, nx]``: the cells a mover covers at snapshot ``k``, by the rule of
    :func:`~dtradar_data.geometry.occupancy.occupancy` (the snapshot's ``blocked`` is the base's obstacles or these)."""
    only_movers = replace(moving.base, objects=moving.boxes_at(k), prisms=(), base=None)
    return occupancy(only_movers)


# ------------------------------------------------------------------------------------------- the work folder
def _stem(work_dir: Path, k: int) -> Path:
    return work_dir / f"snapshot_{k:05d}"


def snapshot_done(work_dir: Path, k: int) -> bool:
    return _stem(work_dir, k).with_suffix(".json").is_file()


def save_snapshot(work_dir: Path, snap: Snapshot) -> None:
    """Write a finished snapshot: tables first, each through a temporary file and a rename, the record last."""
    stem = _stem(work_dir, snap.k)
    tables = [(".cells.parquet", snap.cells)] + ([(".paths.parquet", snap.paths)] if snap.paths is not None else [])
    for suffix, table in tables:
        final = stem.with_name(stem.name + suffix)
        tmp = final.with_name(final.name + f".tmp{os.getpid()}")
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, final)
    final = stem.with_suffix(".json")
    tmp = final.with_name(final.name + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(snap.record, sort_keys=True) + "\n")
    os.replace(tmp, final)
    shutil.rmtree(stem, ignore_errors=True)  # snapshot 0's trace batches: its tables are kept now


def load_snapshot(work_dir: Path, k: int, *, per_path: bool) -> Snapshot | None:
    """A snapshot finished by this or an interrupted earlier build of the same version; None if not finished."""
    stem = _stem(work_dir, k)
    if not snapshot_done(work_dir, k):
        return None
    try:
        record = json.loads(stem.with_suffix(".json").read_text())
        cells = pq.read_table(stem.with_name(stem.name + ".cells.parquet"))
        paths = pq.read_table(stem.with_name(stem.name + ".paths.parquet")) if per_path else None
    except (OSError, ValueError, pa.ArrowException):
        return None  # damaged (a disk filled up): traced again
    return Snapshot(k, cells.replace_schema_metadata(None), paths, record)


def work_progress(work_dir: Path, snapshots: int) -> str:
    """How far the build holding a version's lock has come, from its work folder's finished snapshots."""
    done = len(list(work_dir.glob("snapshot_*.json"))) if work_dir.is_dir() else 0
    return f"it has finished {done} of {snapshots} snapshots"


# ------------------------------------------------------------------------------------------- tracing
def trace_snapshots(
    moving,
    settings,
    work_dir: Path,
    *,
    radius_m: float,
    per_path: bool,
    full_trace: FullTrace,
    progress: bool = True,
    snapshots: int | None = None,
) -> list[Snapshot]:
    """Every snapshot of ``moving`` (the first ``snapshots``, default all): 0 by ``full_trace``, each later one
    differentially from the one before (module docstring); finished snapshots in ``work_dir`` are reused."""
    count = moving.snapshots if snapshots is None else snapshots
    work_dir.mkdir(parents=True, exist_ok=True)
    out: list[Snapshot] = []
    bar = tqdm(total=count, unit="snapshot", desc=f"tracing {moving.name}", disable=not progress)
    with _helpers(moving, settings, work_dir, count) as helpers:
        for k in range(count):
            snap = load_snapshot(work_dir, k, per_path=per_path)
            if snap is None:
                if k == 0:
                    snap = _full_snapshot(moving, work_dir, full_trace)
                else:
                    snap = differential_snapshot(
                        moving, k, out[-1], settings, radius_m=radius_m, per_path=per_path, helpers=helpers
                    )
                save_snapshot(work_dir, snap)
                r = snap.record
                bar.set_postfix_str(f"t={k}: {r['retraced_cells']} of {r['free_cells']} cells traced")
            out.append(snap)
            bar.update(1)
    bar.close()
    return out


def _helpers(moving, settings, work_dir: Path, count: int) -> TraceHelpers:
    """The helper processes that trace parts of each differential snapshot beside this one (:mod:`.trace_helpers`):
    started now, so they load the tracer while snapshot 0 is traced; none when every differential snapshot is done."""
    if all(snapshot_done(work_dir, k) for k in range(1, count)):
        return TraceHelpers(0)
    spec = moving.spec_at(0)
    return TraceHelpers(helper_count(int((~occupancy(spec)).sum()), settings), spec, settings)


def _full_snapshot(moving, work_dir: Path, full_trace: FullTrace) -> Snapshot:
    spec = moving.spec_at(0)
    t0 = time.perf_counter()
    cells, paths, blocked, tracer = full_trace(spec, _stem(work_dir, 0))
    if tracer is not None:
        tracer.close()
    free = int((~blocked).sum())
    record = {
        "t": 0,
        "mode": "full",
        "retraced_cells": free,
        "free_cells": free,
        "reasons": {},
        "movers_moved": [],
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return Snapshot(0, cells, paths, record)


def differential_snapshot(
    moving, k: int, previous: Snapshot, settings, *, radius_m: float, per_path: bool, tracer_factory=None, helpers=None
) -> Snapshot:
    """Snapshot ``k`` from snapshot ``k-1`` (``previous``): the cells around the movers that moved re-traced in
    ``spec_at(k)`` (in row-major order, batches of ``settings.batch_size``, or parts shared with ``helpers``), every
    other row kept."""
    if previous.k != k - 1:
        raise ValueError(f"snapshot {k} is traced from snapshot {k - 1}, not {previous.k}")
    before, spec = moving.spec_at(k - 1), moving.spec_at(k)
    changes = moving.changed_between(k - 1, k)
    changed = [c.before for c in changes] + [c.after for c in changes]
    t0 = time.perf_counter()
    cells, paths, blocked, tracer, mask, counts = differential.retrace(
        previous.cells,
        previous.paths,
        before,
        spec,
        settings,
        radius_m=radius_m,
        per_path=per_path,
        tracer_factory=tracer_factory or (lambda: RayTracer(spec, settings)),
        changed=changed,
        helpers=helpers,
    )
    if tracer is not None:
        tracer.close()
    record = {
        "t": k,
        "mode": "differential",
        "retraced_cells": int(mask.sum()),
        "free_cells": int((~blocked).sum()),
        "reasons": counts,
        "movers_moved": [c.name for c in changes],
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return Snapshot(k, cells, paths, record)


# ------------------------------------------------------------------------------------------- the table
def moving_tables(moving, snaps: list[Snapshot]) -> tuple[pa.Table, pa.Table | None]:
    """The moving-twin tables (:data:`MOVING_CELL_SCHEMA`, :data:`MOVING_PATH_SCHEMA`) of the traced snapshots:
    ``t`` and ``mover`` added, rows sorted by ``(t, iy, ix)`` (and ``path``). ``mover`` must lie inside
    ``blocked`` (:class:`SchemaMismatchError` otherwise: the occupancy rule is one union)."""
    cell_parts, path_parts = [], []
    for snap in snaps:
        n = snap.cells.num_rows
        mover = mover_mask(moving, snap.k).ravel()
        blocked = snap.cells.column("blocked").to_numpy(zero_copy_only=False)
        if mover.size != n or (mover & ~blocked).any():
            raise SchemaMismatchError(
                f"{moving.name} snapshot {snap.k}: the movers' cells are not all blocked",
                hint="a snapshot's blocked mask must be occupancy(spec_at(k)), which includes every mover",
            )
        t = pa.array(np.full(n, snap.k, np.int32), pa.int32())
        cells = snap.cells.append_column("t", t).append_column("mover", pa.array(mover, pa.bool_()))
        cell_parts.append(
            pa.Table.from_arrays([cells.column(f.name) for f in MOVING_CELL_SCHEMA], schema=MOVING_CELL_SCHEMA)
        )
        if snap.paths is not None:
            p = snap.paths.append_column("t", pa.array(np.full(snap.paths.num_rows, snap.k, np.int32), pa.int32()))
            path_parts.append(
                pa.Table.from_arrays([p.column(f.name) for f in MOVING_PATH_SCHEMA], schema=MOVING_PATH_SCHEMA)
            )
    cells = pa.concat_tables(cell_parts).sort_by([("t", "ascending"), ("iy", "ascending"), ("ix", "ascending")])
    paths = None
    if path_parts:
        keys = [("t", "ascending"), ("iy", "ascending"), ("ix", "ascending"), ("path", "ascending")]
        paths = pa.concat_tables(path_parts).sort_by(keys)
    return cells, paths


def build_record(moving, snaps: list[Snapshot], *, radius_m: float) -> dict[str, Any]:
    """What ``meta["moving_build"]`` records: the movers, step and horizon, the rule and radius, and per snapshot
    how it was traced (the card's table)."""
    diff = [s.record for s in snaps if s.record["mode"] == "differential"]
    full = snaps[0].record if snaps else {}
    return {
        "digest": moving.digest(),
        "base": {"variant": moving.base.variant, "digest": moving.base.digest()},
        "dt_s": moving.dt_s,
        "snapshots": moving.snapshots,
        "horizon_s": moving.horizon_s,
        "provenance": moving.provenance,
        "movers": [m.to_dict() for m in moving.movers],
        "rule": differential.RULE,
        "radius_m": max(radius_m, moving.base.grid.cell_m),
        "per_snapshot": [s.record for s in snaps],
        "full_seconds": full.get("seconds"),
        "differential_seconds_mean": round(float(np.mean([r["seconds"] for r in diff])), 3) if diff else None,
        "retraced_cells_mean": round(float(np.mean([r["retraced_cells"] for r in diff])), 1) if diff else None,
        "free_cells_mean": round(float(np.mean([r["free_cells"] for r in diff])), 1) if diff else None,
    }


# ------------------------------------------------------------------------------------------- the animation
def render_gif(moving, cells: pa.Table, path: Path, *, max_frames: int = GIF_MAX_FRAMES) -> Path:
    """An animated GIF of the path gain per cell over time: static obstacles grey, the movers' cells red, one frame
    per snapshot (at most ``max_frames``, evenly picked), ``dt_s`` per frame; the colour scale is shared."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from PIL import Image

    g = moving.base.grid
    h, w = g.ny, g.nx
    count = cells.num_rows // (h * w)
    gain = cells.column("path_gain_db").to_numpy(zero_copy_only=False).astype(float).reshape(count, h, w)
    blocked = cells.column("blocked").to_numpy(zero_copy_only=False).reshape(count, h, w)
    mover = cells.column("mover").to_numpy(zero_copy_only=False).reshape(count, h, w)
    finite = gain[np.isfinite(gain)]
    vmin, vmax = (np.percentile(finite, 2), np.percentile(finite, 99.5)) if finite.size else (-100.0, -40.0)
    x_lo, y_lo = g.x0_m - g.cell_m / 2, g.y0_m - g.cell_m / 2
    extent = (x_lo, x_lo + w * g.cell_m, y_lo, y_lo + h * g.cell_m)
    frames = sorted(set(np.linspace(0, count - 1, min(count, max_frames)).round().astype(int).tolist()))
    width_in = 7.0
    height_in = max(2.5, width_in * h / w * 0.85 + 0.9)
    fig, ax = plt.subplots(figsize=(width_in, height_in), dpi=80)
    im = ax.imshow(gain[0], origin="lower", extent=extent, cmap="viridis", vmin=vmin, vmax=vmax)
    static = blocked[0] & ~mover[0]
    grey = ax.imshow(np.where(static, 1.0, np.nan), origin="lower", extent=extent, cmap=ListedColormap(["0.55"]))
    red = ax.imshow(np.where(mover[0], 1.0, np.nan), origin="lower", extent=extent, cmap=ListedColormap(["#d62728"]))
    fig.colorbar(im, ax=ax, label="path gain [dB]", shrink=0.85)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    images = []
    for k in frames:
        im.set_data(gain[k])
        grey.set_data(np.where(blocked[k] & ~mover[k], 1.0, np.nan))
        red.set_data(np.where(mover[k], 1.0, np.nan))
        ax.set_title(f"{moving.name}: t = {k} ({k * moving.dt_s:g} s); movers red, obstacles grey", fontsize=9)
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        images.append(Image.fromarray(rgba[..., :3].copy()).quantize(colors=128, method=Image.Quantize.MEDIANCUT))
    plt.close(fig)
    step = frames[1] - frames[0] if len(frames) > 1 else 1
    duration_ms = max(100, int(round(moving.dt_s * step * 1000)))
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration_ms, loop=0, optimize=False)
    return path
