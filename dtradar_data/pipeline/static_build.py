"""The static build: a scene's blueprint and dynamic twins (or their antenna-pose-error twins), each traced in full
(:mod:`.tracing`) or, with ``--differential``, re-traced from a stored blueprint (:mod:`.parent`,
:mod:`.differential`), then stored with its coverage map and a city quadrant's overview by the shared store step
(:mod:`.storing`).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError
from dtradar_data.core.ids import DatasetId, format_id
from dtradar_data.core.layout import CELLS_PICTURE_FILE, work_root
from dtradar_data.core.schema import tx_column
from dtradar_data.geometry.floorplan import save_city_overview_png
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.geometry.scene_files import write_stored_scene
from dtradar_data.geometry.xml_transmitter import check_transmitter_in_mesh
from dtradar_data.pipeline import differential
from dtradar_data.pipeline.batches import batch_dir, batch_layout, load_batch
from dtradar_data.pipeline.cells_picture import render_cells_png
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.coverage import render_coverage_png
from dtradar_data.pipeline.executors import check_ray_address
from dtradar_data.pipeline.inputs import build_inputs, city_quadrant_specs, differential_inputs, original_scene
from dtradar_data.pipeline.parent import differential_parent, differential_parent_version
from dtradar_data.pipeline.resources import check_resources
from dtradar_data.pipeline.storing import NewVersion, store_version, version_meta
from dtradar_data.pipeline.tracing import executor_session, trace_scene, work_progress
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import RayTracer
from dtradar_data.scenes import build_targets, load_scene_spec
from dtradar_data.scenes.tx_pose import tx_pose_error
from dtradar_data.store import versions


def build_static(config: BuildConfig) -> list[Dataset]:
    """Build the requested static variant(s) of ``config.scene``; returns the stored datasets.

    Everything that can refuse the build is checked before the first variant is traced, so `all` does not fail
    after the blueprint and a refused build changes nothing on disk: each variant's scene and resources, that
    ``--differential`` has a dynamic twin to apply to and a stored parent with the same inputs (unless this build
    traces that blueprint first), and that a ``--ray-address`` cluster answers."""
    specs = build_specs(config)
    if config.differential:
        _check_parents(specs, config)
    for spec in specs:
        scene_config(config, spec).check_scene(spec)
        check_transmitter_in_mesh(spec)  # an XML scene's own shapes: read for the occupancy below anyway
        cfg = scene_config(config, spec)
        check_resources(
            spec.name,
            int((~occupancy(spec)).sum()),
            cfg.rt,
            work_root(),
            per_path=cfg.per_path,
            transmitters=len(spec.transmitters),
        )
    if config.executor == "ray" and not (config.differential and all(s.variant == "dynamic" for s in specs)):
        check_ray_address(config.ray_address)
    with executor_session(config):
        return [build_one(spec, config) for spec in specs]


def _check_parents(specs: list, config: BuildConfig) -> None:
    """``--differential``: there is a dynamic twin to apply it to, and each one whose blueprint this build does not
    trace first has a stored parent (:func:`differential_parent_version` refuses, naming what differs)."""
    dynamic = [s for s in specs if s.variant == "dynamic"]
    if not dynamic:
        raise InvalidSettingError(
            f"--differential applies to dynamic twins, and {config.scene} has none to build "
            f"(this build traces {', '.join(s.name for s in specs)} in full)",
            hint="drop --differential",
        )
    several = [s.name for s in dynamic if s.more_tx]
    if several:  # its retrace mask follows one transmitter's paths
        raise InvalidSettingError(
            f"--differential re-traces twins with one transmitter, and {several[0]} has several",
            hint="drop --differential: the dynamic twin is then traced in full (every transmitter at once)",
        )
    traced_first = {s.scene for s in specs if s.variant == "blueprint"}
    for spec in dynamic:
        if spec.scene not in traced_first:
            differential_parent_version(spec, config)


def build_specs(config: BuildConfig) -> list:
    """The scene specs ``build(config)`` traces, in order: the requested variants, each made an antenna-pose-error
    twin with ``--tx-pose-error`` (every variant with the same transmitter pose)."""
    specs = [
        load_scene_spec(scene, v, footprints=config.osm, cell_m=config.cell_m, grid=config.grid, tx=config.tx)
        for scene, v in build_targets(config.scene, config.variant)
    ]
    if config.tx_pose_error is None:
        return specs
    offset_m, angle_deg = config.tx_pose_error
    specs = [tx_pose_error(s, offset_m=offset_m, angle_deg=angle_deg, seed=config.tx_pose_seed) for s in specs]
    poses: dict[str, object] = {}
    for s in specs:  # the draw skips places inside objects, and the variants' objects differ: never in practice
        if poses.setdefault(s.scene, s.tx) != s.tx:
            raise InvalidCoordinatesError(
                f"--tx-pose-error: the seeded pose of {s.name} differs from that of its other variant (an object of "
                "one variant stands where the other's transmitter moved)",
                hint="build with another --tx-pose-seed",
            )
    return specs


@dataclass(frozen=True)
class _Job:
    """One variant of one scene to build: its spec, its config (the scene's RT defaults filled in), its id, inputs
    and version, and with ``--differential`` the stored parent it starts from and the parent's scene."""

    spec: object
    config: BuildConfig
    ds_id: DatasetId
    inputs: dict
    version: str
    parent: Dataset | None = None
    parent_spec: object = None


@dataclass(frozen=True)
class _Traced:
    """What the trace step returns: the tables, ``blocked``, the tracer (if one was made), how long it took, and
    what the card records about a differential trace."""

    cells: pa.Table
    paths: pa.Table | None
    blocked: np.ndarray
    tracer: object
    seconds: float
    extra_meta: dict


def build_one(spec, config: BuildConfig) -> Dataset:
    """Build (or reuse) one variant of one scene."""
    config = scene_config(config, spec)
    config.check_scene(spec)
    ds_id = DatasetId(spec.scene, spec.variant, None)
    inputs = build_inputs(spec, config)
    parent = parent_spec = None
    if config.differential and spec.variant == "dynamic":
        parent, parent_spec = differential_parent(spec, config)
        inputs = differential_inputs(inputs, parent.version, config)
    job = _Job(spec, config, ds_id, inputs, versions.version_id(inputs), parent, parent_spec)
    return store_version(
        ds_id,
        job.version,
        functools.partial(_make, job),
        progress=lambda work_dir: work_progress(work_dir, spec, config.rt),
        how=" (differential)" if parent is not None else "",
        rt=config.rt,
    )


def _make(job: _Job, work_dir: Path, tmp: Path) -> NewVersion:
    """The store step's ``make``: trace, then draw the extra files and write the metadata."""
    traced = _trace_differential(job) if job.parent is not None else _trace_full(job, work_dir)
    return _new_version(job, work_dir, tmp, traced)


def _trace_full(job: _Job, work_dir: Path) -> _Traced:
    t0 = time.perf_counter()
    cells, paths, blocked, tracer = trace_scene(job.spec, job.config, work_dir)
    return _Traced(cells, paths, blocked, tracer, time.perf_counter() - t0, {})


def _trace_differential(job: _Job) -> _Traced:
    """Re-trace only the cells the changed objects can affect; every other row is the parent's (always in this
    process: the few re-traced cells are not worth Ray's start)."""
    spec, config = job.spec, job.config
    t0 = time.perf_counter()
    cells, paths, blocked, tracer, record = differential.differential_trace(
        job.parent,
        job.parent_spec,
        spec,
        config.rt,
        radius_m=config.retrace_radius_m,
        per_path=config.per_path,
        tracer_factory=lambda: RayTracer(spec, config.rt),
    )
    print(
        f"{format_id(job.ds_id)}: re-traced {record['retraced_cells']} of {record['free_cells']} free cells "
        f"(parent {record['parent']})"
    )
    return _Traced(cells, paths, blocked, tracer, time.perf_counter() - t0, {"differential": record})


def _new_version(job: _Job, work_dir: Path, tmp: Path, traced: _Traced) -> NewVersion:
    """Write the scene, render the coverage map and a city quadrant's overview into ``tmp``, then the metadata: after
    the map, since the metadata records the Mitsuba variant, which the map's tracer sets when every batch was
    reused."""
    spec, config = job.spec, job.config
    settings = config.rt
    tracer = traced.tracer
    # the scene the tables were traced from, as the tracer wrote it, made self-contained (plain Sionna opens it)
    extra = write_stored_scene(spec, tmp / "scene")
    if config.coverage_map:
        if tracer is None:
            tracer = RayTracer(spec, settings)
        extra["coverage.png"] = render_coverage_png(spec, tracer, tmp / "coverage.png", samples=config.coverage_samples)
    # the table itself, cell for cell (cheap: no tracer), so a hole the radio map smooths over shows
    extra[CELLS_PICTURE_FILE] = render_cells_png(spec, traced.cells, traced.blocked, tmp / CELLS_PICTURE_FILE)
    if spec.prisms and "city" in spec.provenance:
        extra["city.png"] = save_city_overview_png(
            city_quadrant_specs(spec, config), tmp / "city.png", highlight=original_scene(spec)
        )
    num_free = int((~traced.blocked).sum())
    meta = {
        **version_meta(spec, settings, format_id(job.ds_id), job.version, job.inputs),
        **traced.extra_meta,
        "build_inputs_hash": job.version,
        "stats": {
            "num_cells": int(traced.blocked.size),
            "num_free": num_free,
            **_with_paths(traced.cells, len(spec.transmitters)),
            "num_paths_total": traced.paths.num_rows if traced.paths is not None else None,
            "trace_seconds": round(traced.seconds, 2),
            **(_retraced(work_dir, settings, num_free) if settings.batch_independent else {}),
        },
    }
    return NewVersion(traced.cells, traced.paths, meta, extra, tracer)


def _retraced(work_dir: Path, settings: RTSettings, free_cells: int) -> dict[str, int]:
    """How many cells a batch-independent build re-traced because their call's path buffer filled (the batch files'
    ``retrace_depth``, of this build's layout only), for the card."""
    where = batch_dir(work_dir, settings, batch_layout(free_cells, settings))
    depth = [load_batch(p)[0].get("retrace_depth") for p in sorted(where.glob("batch_*.npz"))]
    depth = [d for d in depth if d is not None]
    if not depth:
        return {}
    d = np.concatenate(depth)
    return {"cells_retraced_for_full_path_buffer": int((d != 0).sum()), "cells_filling_it_alone": int((d < 0).sum())}


def _with_paths(cells: pa.Table, transmitters: int) -> dict:
    """``num_with_paths``: the cells with a path from at least one transmitter; with several, also how many each
    transmitter reaches (``num_with_paths_per_tx``, transmitter 0 first)."""
    each = [cells.column(tx_column("num_paths", k)).to_numpy() > 0 for k in range(transmitters)]
    out = {"num_with_paths": int(np.count_nonzero(np.logical_or.reduce(each)))}
    if transmitters > 1:
        out["num_with_paths_per_tx"] = [int(np.count_nonzero(e)) for e in each]
    return out
