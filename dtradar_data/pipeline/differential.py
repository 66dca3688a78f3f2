"""Differential re-tracing: rebuild a changed twin by re-tracing only the cells whose radio features can change.

A dynamic twin is its blueprint plus a few added, moved or removed objects. A cell's strongest path and total gain
can only change when a changed object (its old or new place) touches a path that reaches the cell, so
:func:`retrace_mask` selects, from geometry and the parent's stored table alone:

1. cells whose occupancy changed (an object now stands there, or no longer does);
2. cells within ``radius_m`` (at least one cell size) of a changed object (its reflections and shadow nearby);
3. cells whose line of sight from the transmitter passes within that distance of a changed object;
4. cells whose stored strongest path leaves the transmitter (its departure angles) towards a changed object, so a
   reflected path's first leg may now be blocked or reflected elsewhere.

Every other cell keeps the parent version's row (and its per-path rows). What this misses are weaker paths' changes
away from these cells and second legs of reflections; the README reports the agreement with a full re-trace. The
dataset's card records the parent version, the rule and radius, and how many cells were re-traced for each reason.

The kept rows are the parent's, traced with the parent's inputs, while the card names this build's. So a parent is
used only when every input its rows depend on equals this build's (:func:`inherited_differences`): the scene except
its objects (grid, transmitter, heights, room, buildings, base mesh), every RT setting that feeds the version (the
frequency, depth, samples, seed, batch size ...), the schema and library versions, and the per-path table.

A moving twin (:mod:`dtradar_data.pipeline.moving`) re-traces each snapshot from the one before with
:func:`retrace`, the changed objects being the movers' old and new boxes.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import shapely
from shapely.geometry import Polygon

from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline.batches import trace_batch
from dtradar_data.rt import features

RULE = 1  # bump when retrace_mask changes what it selects (it is part of the version)
REASONS = ("occupancy", "near", "line_of_sight", "departure")
#: Scene fields a dynamic twin may change from its blueprint: its objects, and the words that name and describe it.
#: Every other field (grid, tx, heights, room, prisms, base, and any added later) must equal the parent's.
MAY_DIFFER = ("objects", "scene", "variant", "title", "description", "source", "licence", "attribution")


def inherited_differences(
    parent_meta: dict,
    scene_spec: dict,
    rt: dict,
    *,
    schema_version: int,
    libraries: dict,
    per_path: bool,
    parent_has_paths: bool,
) -> list[str]:
    """What the parent's rows were made with that this build would make differently, one phrase each (parent's
    value first); empty when its kept rows are what this build would have traced. ``scene_spec`` and ``rt`` are this
    build's ``SceneSpec.to_dict()`` and ``RTSettings.hashed()``; ``parent_meta`` is the parent's ``meta.json``."""
    out = []
    recorded = parent_meta.get("scene_spec") or {}
    for key in sorted((set(recorded) | set(scene_spec)) - set(MAY_DIFFER)):
        if recorded.get(key) != scene_spec.get(key):
            out.append(_differs(f"scene {key}", recorded.get(key), scene_spec.get(key)))
    parent_rt = parent_meta.get("rt") or {}
    engine, parent_engine = rt.get("batch_independent"), parent_rt.get("batch_independent")
    if engine != parent_engine:  # one traced with Sionna's own solver, the other batch-independently
        out.append(f"the solver: the parent was traced {_engine(parent_engine)}, this build traces {_engine(engine)}")
    for key in rt:
        if key != "batch_independent" and parent_rt.get(key, _MISSING) != rt[key]:
            out.append(_differs("--rt." + key.replace("_", "-"), parent_rt.get(key, _MISSING), rt[key]))
    if parent_meta.get("schema_version") != schema_version:
        out.append(_differs("schema version", parent_meta.get("schema_version"), schema_version))
    parent_libs = parent_meta.get("library_versions") or {}
    for lib in sorted(set(parent_libs) | set(libraries)):
        if parent_libs.get(lib, _MISSING) != libraries.get(lib, _MISSING):
            out.append(_differs(lib, parent_libs.get(lib, _MISSING), libraries.get(lib, _MISSING)))
    if per_path and not parent_has_paths:
        out.append("the per-path table: the parent has none (built with --no-per-path), this build stores one")
    return out


def _engine(recorded) -> str:
    if recorded is None:
        return "with Sionna's own solver (--rt.no-batch-independent)"
    return f"batch-independently ({recorded})"


class _Missing:
    def __repr__(self) -> str:
        return "(not recorded)"


_MISSING = _Missing()


def _differs(what: str, parent, here) -> str:
    def show(v) -> str:
        return f"{v:g}" if isinstance(v, float) else str(v) if isinstance(v, (str, _Missing)) else repr(v)

    a, b = show(parent), show(here)
    if len(a) + len(b) > 80:
        return f"{what} differs"
    return f"{what} {a} in the parent, {b} here"


def changed_boxes(parent_spec, spec) -> list:
    """Objects (boxes) present in one spec and not identically in the other: added, removed, old and new places."""
    before = {b.name: b for b in parent_spec.objects}
    after = {b.name: b for b in spec.objects}
    out = [b for n, b in after.items() if before.get(n) != b]
    out += [b for n, b in before.items() if after.get(n) != b]
    return out


def _segment_hits_box(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Slab test of segments ``p0[i] -> p1[i]`` (float[N, 3]) against one axis-aligned box: bool[N]."""
    d = p1 - p0
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo - p0) / d
        t1 = (hi - p0) / d
    tmin = np.where(d == 0, np.where((p0 >= lo) & (p0 <= hi), -np.inf, np.inf), np.minimum(t0, t1))
    tmax = np.where(d == 0, np.where((p0 >= lo) & (p0 <= hi), np.inf, -np.inf), np.maximum(t0, t1))
    enter, leave = tmin.max(axis=1), tmax.min(axis=1)
    return (enter <= leave) & (leave >= 0) & (enter <= 1)


def retrace_mask(
    parent_spec, spec, parent_cells: pa.Table, *, radius_m: float, changed: list | None = None
) -> tuple[np.ndarray, dict]:
    """bool[ny, nx] of the free cells to re-trace, and how many cells each reason selected (see module doc).
    ``changed``: the changed boxes (old and new places) when the caller knows them (a moving twin's movers between
    two snapshots); by default :func:`changed_boxes` of the two specs."""
    g = spec.grid
    radius_m = max(radius_m, g.cell_m)  # at metre-sized city cells a smaller radius reaches no neighbouring centre
    blocked = occupancy(spec)
    changed = changed_boxes(parent_spec, spec) if changed is None else list(changed)
    xs, ys = g.centres()
    cx, cy = np.meshgrid(xs, ys)
    reasons = {r: np.zeros(g.shape, bool) for r in REASONS}
    reasons["occupancy"] = blocked != occupancy(parent_spec)
    if changed:
        tx = np.asarray(spec.tx.position_m, dtype=float)
        rx = np.stack([cx.ravel(), cy.ravel(), np.full(cx.size, spec.rx_height_m)], axis=1)
        zen, az, tau = (_column(parent_cells, k).astype(float) for k in ("aod_zen_rad", "aod_az_rad", "tau_s"))
        has_path = ~np.isnan(tau)
        zen, az, tau = (np.nan_to_num(v, nan=0.0) for v in (zen, az, tau))
        direction = np.stack([np.sin(zen) * np.cos(az), np.sin(zen) * np.sin(az), np.cos(zen)], axis=1)
        # the first leg of the strongest path, at most as long as the whole path (delay x speed of light)
        first_leg_end = tx + direction * (tau * 299_792_458.0)[:, None]
        for box in changed:
            footprint = Polygon(box.corners())
            reasons["near"] |= (
                shapely.distance(footprint, shapely.points(cx.ravel(), cy.ravel())) <= radius_m
            ).reshape(g.shape)
            corners = box.corners()
            lo = np.array([corners[:, 0].min(), corners[:, 1].min(), box.z_m]) - radius_m
            hi = np.array([corners[:, 0].max(), corners[:, 1].max(), box.top_m]) + radius_m
            starts = np.repeat(tx[None, :], len(rx), axis=0)
            reasons["line_of_sight"] |= _segment_hits_box(starts, rx, lo, hi).reshape(g.shape)
            reasons["departure"] |= (_segment_hits_box(starts, first_leg_end, lo, hi) & has_path).reshape(g.shape)
    mask = np.zeros(g.shape, bool)
    for r in REASONS:
        mask |= reasons[r]
    mask &= ~blocked  # a cell that is now blocked is not traced: it only loses its radio features
    counts = {r: int((reasons[r] & ~blocked).sum()) for r in REASONS}
    return mask, counts


def differential_trace(parent, parent_spec, spec, settings, *, radius_m: float, per_path: bool, tracer_factory):
    """``(cells, paths, blocked, tracer, record)``: the parent's tables with the selected cells re-traced."""
    cells_tbl, paths_tbl, blocked, tracer, mask, counts = retrace(
        parent.table,
        parent.paths_table if per_path else None,
        parent_spec,
        spec,
        settings,
        radius_m=radius_m,
        per_path=per_path,
        tracer_factory=tracer_factory,
    )
    record = {
        "parent": f"{parent.name}@{parent.version}",
        "rule": RULE,
        "radius_m": max(radius_m, spec.grid.cell_m),
        "retraced_cells": int(mask.sum()),
        "free_cells": int((~blocked).sum()),
        "reasons": counts,
    }
    return cells_tbl, paths_tbl, blocked, tracer, record


def retrace(
    parent_cells: pa.Table,
    parent_paths: pa.Table | None,
    parent_spec,
    spec,
    settings,
    *,
    radius_m: float,
    per_path: bool,
    tracer_factory,
    changed: list | None = None,
    helpers=None,
):
    """``(cells, paths, blocked, tracer, mask, counts)``: the parent's per-cell table (and per-path table, with
    ``per_path``) with the cells :func:`retrace_mask` selects re-traced in ``spec``, in batches of
    ``settings.batch_size`` in row-major order; ``tracer_factory()`` makes the tracer of ``spec`` (only when a cell
    is re-traced; ``tracer`` is None otherwise). ``changed`` as for :func:`retrace_mask`. ``helpers``
    (:class:`~dtradar_data.pipeline.trace_helpers.TraceHelpers`): other processes trace parts of the cells at the
    same time, where the rows do not depend on the parts (batch-independent tracing)."""
    blocked = occupancy(spec)
    mask, counts = retrace_mask(parent_spec, spec, parent_cells, radius_m=radius_m, changed=changed)
    xs, ys = spec.grid.centres()
    free_iy, free_ix = np.nonzero(~blocked)
    merged = {k: _column(parent_cells, k)[~blocked.ravel()] for k in features.CELL_RADIO_KEYS}
    todo = np.flatnonzero(mask[free_iy, free_ix])  # positions among the free cells, row-major
    tracer, new_paths = None, []
    if len(todo):
        tracer = tracer_factory()
        ix, iy = free_ix[todo], free_iy[todo]
        points = np.stack([xs[ix], ys[iy], np.full(len(todo), spec.rx_height_m)], axis=1)
        tracer.check_points(points)
        for sl, (cells, paths) in _traced(tracer, spec, settings, points, ix, iy, per_path=per_path, helpers=helpers):
            for k in features.CELL_RADIO_KEYS:
                merged[k][todo[sl]] = cells[k]
            if per_path:
                new_paths.append(paths)
    cells_tbl = features.cells_table(xs, ys, blocked, merged)
    paths_tbl = None
    if per_path:
        paths_tbl = features.paths_table([_keep_parent_paths(parent_paths, mask | blocked), *new_paths])
    return cells_tbl, paths_tbl, blocked, tracer, mask, counts


def _traced(tracer, spec, settings, points, ix, iy, *, per_path: bool, helpers):
    """``(slice, (cells, paths))`` of each trace call over ``points``: batches of ``settings.batch_size`` in this
    process, or parts shared with ``helpers`` when they take them."""
    if helpers is not None and helpers.splits(len(points), settings):
        return helpers.trace(tracer, spec, settings, points, ix, iy, per_path=per_path)
    batches = [slice(s, s + settings.batch_size) for s in range(0, len(points), settings.batch_size)]
    return ((sl, trace_batch(tracer, points[sl], ix[sl], iy[sl], per_path=per_path)) for sl in batches)


def _column(table: pa.Table, name: str) -> np.ndarray:
    """A radio column as a writable numpy array over all cells (nulls as the reduction's 'no path' values)."""
    col = table.column(name)
    arr = col.to_numpy(zero_copy_only=False)
    if arr.dtype == object:
        arr = np.array([np.nan if v is None else v for v in arr], dtype=float)
    return np.array(arr, copy=True)


def _keep_parent_paths(paths: pa.Table, drop: np.ndarray) -> dict[str, np.ndarray]:
    """The parent's per-path rows of the cells not re-traced, as the arrays :func:`features.paths_table` takes."""
    ix = paths.column("ix").to_numpy()
    iy = paths.column("iy").to_numpy()
    keep = ~drop[iy, ix]
    return {name: paths.column(name).to_numpy(zero_copy_only=False)[keep] for name in paths.column_names}
