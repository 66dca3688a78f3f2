"""The trace step: every free cell of a scene's grid through the ray tracer, in receiver batches, into the per-cell
table (and the per-path table).

Each finished batch is kept in the build's work folder, so an interrupted build continues where it stopped.
``executor="ray"`` traces the batches still missing there as Ray tasks first (:mod:`.executors`), then assembles the
table from the work folder exactly as a serial build does: both give the same table and version.
"""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm.auto import tqdm

from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.geometry.xml_meshes import ground_height
from dtradar_data.pipeline.batches import (
    DamagedBatchError,
    batch_dir,
    batch_layout,
    batch_path,
    load_batch,
    save_batch,
    trace_batch,
)
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.executors import RaySession, trace_on_ray
from dtradar_data.rt import features
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import RayTracer


class _Receivers(NamedTuple):
    """A grid's free cells as receivers: ``blocked``, the cell centres, and the free cells' indices and points."""

    blocked: np.ndarray
    xs: np.ndarray
    ys: np.ndarray
    ix: np.ndarray
    iy: np.ndarray
    points: np.ndarray


def trace_grid(
    spec,
    settings: RTSettings,
    work_dir: Path | None = None,
    *,
    per_path: bool = True,
    progress: bool = True,
    tracer=None,
    executor: str = "serial",
    ray_address: str | None = None,
    workers: int = 0,
):
    """Trace every free cell of ``spec``'s grid. Returns ``(cells, paths, blocked, tracer)``.

    With ``work_dir``, each finished batch is saved there and reused on the next call (resumable). ``executor="ray"``
    traces the missing batches as Ray tasks first (:mod:`dtradar_data.pipeline.executors`; needs ``work_dir``), then
    assembles the table from the work folder exactly as a serial build does.
    """
    rx = _receivers(spec)
    size = batch_layout(len(rx.points), settings)
    n_batches = max(1, -(-len(rx.points) // size))
    if work_dir is not None:
        work_dir = batch_dir(work_dir, settings, size)
        work_dir.mkdir(parents=True, exist_ok=True)
    cell_parts, path_parts = [], []
    bar = tqdm(total=len(rx.points), unit="cell", desc=f"ray tracing {spec.name}", disable=not progress)
    on_ray: set[int] = set()
    if executor == "ray":
        if work_dir is None:
            raise InvalidSettingError("--executor ray needs a work folder", hint="build through build()/build_one()")
        on_ray = {b for b in range(n_batches) if not batch_path(work_dir, b).exists()}
        trace_on_ray(
            spec,
            settings,
            rx.points,
            rx.ix,
            rx.iy,
            work_dir,
            sorted(on_ray),
            size=size,
            per_path=per_path,
            address=ray_address,
            workers=workers,
            bar=bar,
        )
    elif executor != "serial":
        raise InvalidSettingError(f"--executor {executor!r} is not an executor", hint="use serial or ray")
    for b in range(n_batches):
        sl = slice(b * size, (b + 1) * size)
        cache = batch_path(work_dir, b) if work_dir is not None else None
        cells, paths, tracer = _load_or_trace(cache, spec, settings, rx, sl, tracer, per_path=per_path)
        cell_parts.append(cells)
        if per_path:
            path_parts.append(paths)
        if b not in on_ray:  # the Ray executor advanced the bar as its batches finished
            bar.update(len(rx.points[sl]))
    bar.close()
    k = len(spec.transmitters)
    merged = {key: np.concatenate([c[key] for c in cell_parts]) for key in features.radio_keys(k)}
    cells_tbl = features.cells_table(rx.xs, rx.ys, rx.blocked, merged, k)
    paths_tbl = features.paths_table(path_parts, k) if per_path else None
    return cells_tbl, paths_tbl, rx.blocked, tracer


def _receivers(spec) -> _Receivers:
    """The free cells of ``spec``'s grid in row-major order, each a receiver point; none free is refused."""
    blocked = occupancy(spec)
    xs, ys = spec.grid.centres()
    iy, ix = np.nonzero(~blocked)  # row-major order of the free cells
    # rx_height_m above the ground: 0 indoors and on flat cities, the terrain under an XML scene's cells
    points = np.stack([xs[ix], ys[iy], spec.rx_height_m + ground_height(spec, xs[ix], ys[iy])], axis=1)
    if len(points) == 0:
        raise InvalidCoordinatesError(
            f"all {blocked.size} cells of {spec.name} are blocked: nothing to trace",
            hint="use smaller cells (--cell-m for a city) or fix the grid in the scene file",
        )
    return _Receivers(blocked, xs, ys, ix, iy, points)


def _load_or_trace(cache: Path | None, spec, settings: RTSettings, rx: _Receivers, sl: slice, tracer, *, per_path):
    """Batch ``sl``: loaded from its ``cache`` file when an earlier run (or a Ray worker) finished it, else traced in
    this process (the tracer made at the first such batch) and saved there. Returns ``(cells, paths, tracer)``."""
    if cache is not None and cache.exists():
        try:
            cells, paths = load_batch(cache)
            return cells, paths, tracer
        except DamagedBatchError as e:  # traced again below and rewritten: a damaged file never enters a table
            print(f"a finished batch cannot be used: {e}; tracing it again", file=sys.stderr, flush=True)
    if tracer is None:
        tracer = RayTracer(spec, settings)
        tracer.check_points(rx.points)  # the cheap check, once, before the first expensive trace
    cells, paths = trace_batch(tracer, rx.points[sl], rx.ix[sl], rx.iy[sl], per_path=per_path)
    if cache is not None:
        save_batch(cache, cells, paths)
    return cells, paths, tracer


def trace_scene(spec, config: BuildConfig, work_dir: Path):
    """:func:`trace_grid` of ``spec`` with a build's settings (executor included), resumable in ``work_dir``."""
    return trace_grid(
        spec,
        config.rt,
        work_dir,
        per_path=config.per_path,
        progress=config.progress,
        executor=config.executor,
        ray_address=config.ray_address,
        workers=config.workers,
    )


def work_progress(work_dir: Path, spec, settings: RTSettings) -> str:
    """How far the build holding a version's lock has come, from its work folder's finished batch files."""
    free = int((~occupancy(spec)).sum())
    size = batch_layout(free, settings)
    where = batch_dir(work_dir, settings, size)
    done = len(list(where.glob("batch_*.npz"))) if where.is_dir() else 0
    if not done:
        return "it has finished no trace batch yet"
    return f"it has finished {done} of {-(-free // size)} trace batches"


def executor_session(config: BuildConfig):
    """The context a build's scenes are traced in: with ``--executor ray`` one :class:`RaySession` for all of them
    (Ray started once, its workers warm from one scene to the next), else nothing."""
    if config.executor == "ray":
        return RaySession(config.ray_address, config.workers)
    return contextlib.nullcontext()
