"""The moving build: a scene's moving twin, snapshot 0 traced in full (:mod:`.tracing`) and each later snapshot
differentially from the one before (:mod:`.moving`), resumable snapshot by snapshot, then stored as one version with
its animation by the shared store step (:mod:`.storing`).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.ids import MOVING_VARIANT, DatasetId, format_id
from dtradar_data.core.layout import work_root
from dtradar_data.core.schema import MOVING_SCHEMA_VERSION
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import moving
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.executors import check_ray_address
from dtradar_data.pipeline.inputs import moving_build_inputs
from dtradar_data.pipeline.resources import check_resources
from dtradar_data.pipeline.storing import NewVersion, store_version, version_meta
from dtradar_data.pipeline.tracing import executor_session, trace_scene
from dtradar_data.scenes import build_targets, load_moving_scene
from dtradar_data.scenes.moving_scene import MAX_SNAPSHOTS
from dtradar_data.store import versions


def build_moving(config: BuildConfig, *, snapshots: int | None = None) -> list[Dataset]:
    """Build (or reuse) the moving twin(s) of ``config.scene``: every check (scene, resources, Ray cluster) before
    the first trace. ``snapshots`` (tests, quick looks): only the first this many snapshots (a twin of its own:
    its scene says so, so it has its own version)."""
    if config.rt.path_channels:  # the moving schemas have no channel columns yet: refused before any trace
        raise InvalidSettingError(
            "--rt.path-channels is for static twins in this version (a moving twin stores no channel columns)",
            hint="build the moving twin without --rt.path-channels, or its blueprint with it",
        )
    scenes = moving_scenes(config)
    if snapshots is not None:
        scenes = [_cut_short(m, snapshots) for m in scenes]
    for m in scenes:
        cfg = scene_config(config, m.base)
        spec0 = m.spec_at(0)
        cfg.check_scene(spec0)
        free = int((~occupancy(spec0)).sum()) * m.snapshots
        check_resources(m.name, free, cfg.rt, work_root(), per_path=cfg.per_path)
    if config.executor == "ray":
        check_ray_address(config.ray_address)
    with executor_session(config):
        return [build_moving_one(m, config) for m in scenes]


def moving_scenes(config: BuildConfig) -> list:
    """The moving twins ``build(config)`` with ``variant="moving"`` traces (a city's: its ``[moving]`` quadrant's),
    over ``config.horizon_s`` when given."""
    scenes = [
        load_moving_scene(scene, footprints=config.osm, cell_m=config.cell_m)
        for scene, _ in build_targets(config.scene, MOVING_VARIANT)
    ]
    return scenes if config.horizon_s is None else [with_horizon(m, config.horizon_s) for m in scenes]


def with_horizon(moving_scene, horizon_s: float):
    """``moving_scene`` over ``horizon_s`` seconds (``--horizon-s``): whole steps of its ``dt_s``, 1 to
    :data:`~dtradar_data.scenes.moving_scene.MAX_SNAPSHOTS`, else :class:`InvalidSettingError` saying which horizon
    fits."""
    dt = moving_scene.dt_s
    snapshots = round(horizon_s / dt)
    if not 1 <= snapshots <= MAX_SNAPSHOTS:
        raise InvalidSettingError(
            f"--horizon-s {horizon_s:g} makes {snapshots} snapshots of {moving_scene.name} (one per robot step of "
            f"{dt:g} s); a moving twin has 1 to {MAX_SNAPSHOTS}",
            hint=f"give --horizon-s between {dt:g} and {MAX_SNAPSHOTS * dt:g}, or drop it for the movers' common "
            f"period ({moving_scene.horizon_s:g} s)",
        )
    provenance = {**moving_scene.provenance, "snapshots": snapshots, "horizon_from": "--horizon-s"}
    return dataclasses.replace(moving_scene, snapshots=snapshots, provenance=provenance)


def _cut_short(moving_scene, snapshots: int):
    """``moving_scene``'s first ``snapshots`` snapshots; its provenance says so, so its version is its own."""
    n = min(snapshots, moving_scene.snapshots)
    provenance = {**moving_scene.provenance, "snapshots": n, "horizon_from": "cut short"}
    return dataclasses.replace(moving_scene, snapshots=n, provenance=provenance)


def build_moving_one(moving_scene, config: BuildConfig) -> Dataset:
    """Build (or reuse) one moving twin: snapshot by snapshot, resumable (:mod:`.moving`), then one version."""
    config = scene_config(config, moving_scene.base)
    config.check_scene(moving_scene.spec_at(0))
    ds_id = DatasetId(moving_scene.scene, MOVING_VARIANT, None)
    inputs = moving_build_inputs(moving_scene, config)
    version = versions.version_id(inputs)
    return store_version(
        ds_id,
        version,
        functools.partial(_make, moving_scene, config, format_id(ds_id), version, inputs),
        progress=lambda work_dir: moving.work_progress(work_dir, moving_scene.snapshots),
        rt=config.rt,
    )


def _make(moving_scene, config: BuildConfig, name: str, version: str, inputs: dict, work_dir: Path, tmp: Path):
    """The store step's ``make``: trace every snapshot, join them into one table, its metadata and animation."""
    t0 = time.perf_counter()
    snaps = moving.trace_snapshots(
        moving_scene,
        config.rt,
        work_dir,
        radius_m=config.retrace_radius_m,
        per_path=config.per_path,
        full_trace=functools.partial(_full_trace, config),
        progress=config.progress,
    )
    trace_s = time.perf_counter() - t0
    cells, paths = moving.moving_tables(moving_scene, snaps)
    meta = {
        **version_meta(moving_scene.base, config.rt, name, version, inputs),
        "variant": MOVING_VARIANT,
        "title": moving_scene.title,
        "description": moving_scene.description,
        "scene_spec": moving_scene.base.to_dict(),
        "scene_hash": moving_scene.digest(),
        "moving_schema_version": MOVING_SCHEMA_VERSION,
        "moving": {
            "snapshots": moving_scene.snapshots,
            "dt_s": float(moving_scene.dt_s),
            "movers": [m.name for m in moving_scene.movers],
        },
        "moving_build": moving.build_record(moving_scene, snaps, radius_m=config.retrace_radius_m),
        "build_inputs_hash": version,
        "stats": _stats(moving_scene, snaps, cells, paths, trace_s),
    }
    gif = moving.render_gif(moving_scene, cells, tmp / moving.GIF_FILE)
    return NewVersion(cells, paths, meta, {moving.GIF_FILE: gif})


def _full_trace(config: BuildConfig, spec, batch_dir: Path):
    """How snapshot 0 is traced: as a static build traces a scene (the build's executor too), resumable by batch."""
    return trace_scene(spec, config, batch_dir)


def _stats(moving_scene, snaps: list, cells, paths, trace_s: float) -> dict:
    """The card's counts of a moving twin: cells and paths over every snapshot, and the trace time."""
    spec0 = moving_scene.spec_at(0)
    return {
        "num_cells": cells.num_rows,
        "num_free": sum(s.record["free_cells"] for s in snaps),
        "num_with_paths": int(np.count_nonzero(cells.column("num_paths").to_numpy() > 0)),
        "num_paths_total": paths.num_rows if paths is not None else None,
        "trace_seconds": round(trace_s, 2),
        "snapshots": moving_scene.snapshots,
        "cells_per_snapshot": spec0.grid.nx * spec0.grid.ny,
    }
