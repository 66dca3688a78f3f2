"""Scene → meshes → Sionna RT over the grid → per-cell table → versioned Parquet in the data root.

``build(BuildConfig(scene="cubicle"))`` builds both static variants; ``variant="moving"`` builds the moving twin
instead (snapshot 0 in full, each later snapshot differentially from the one before: :mod:`.moving`). The version of
a dataset is the hash of its inputs (scene description, RT settings, schema version, library versions), computed
before any tracing: building the same thing twice reuses the stored version. Tracing runs in receiver batches; each
finished batch is kept under ``<data root>/work/`` so an interrupted build continues where it stopped, and the work
folder is removed once the version is stored.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm.auto import tqdm

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    InvalidCoordinatesError,
    InvalidSettingError,
)
from dtradar_data.core.files import waiting_lock
from dtradar_data.core.ids import MOVING_VARIANT, DatasetId, format_id
from dtradar_data.core.layout import PATHS_FILE, data_root, refs_path, version_dir, work_root
from dtradar_data.core.schema import MOVING_SCHEMA_VERSION, SCHEMA_VERSION
from dtradar_data.geometry.floorplan import save_city_overview_png
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.geometry.xml_meshes import ground_height
from dtradar_data.pipeline import differential, moving
from dtradar_data.pipeline.batches import batch_dir, batch_layout, batch_path, load_batch, save_batch, trace_batch
from dtradar_data.pipeline.coverage import COVERAGE_SUBCELLS, render_coverage_png
from dtradar_data.pipeline.executors import RaySession, check_ray_address, import_ray, trace_on_ray
from dtradar_data.pipeline.resources import check_resources
from dtradar_data.rt import features
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import RayTracer, active_variant
from dtradar_data.scenes import build_targets, load_moving_scene, load_scene_spec
from dtradar_data.scenes.model import Box
from dtradar_data.scenes.movers import MAX_SNAPSHOTS
from dtradar_data.scenes.options import check_scene_options
from dtradar_data.scenes.tx_pose import check_tx_pose_error, tx_pose_error
from dtradar_data.store import local, versions, writing

REDUCTION_DOC = (
    "path power = |a|^2 averaged over all (RX port, TX port) pairs; strongest path = largest path power; "
    "a_re/a_im/phase_rad = coefficient of the strongest path at RX port 0 / TX port 0 (first element, first "
    "polarisation); path_gain_db = 10 log10 of the sum of path powers; delay_spread_s = power-weighted RMS delay spread"
)


@dataclass(frozen=True)
class BuildConfig:
    """Ray-trace a scene into the data root (both variants unless one is named)."""

    scene: str = "cubicle"
    """A built-in scene (cubicle, meeting), a city (dallas, houston: its four quadrants and its dynamic twin), one
    city quadrant (dallas-q3), a scene bundled with Sionna (sionna:munich, sionna:etoile, sionna:florence,
    sionna:san_francisco, sionna:simple_street_canyon), or the path of your own scene file (.toml) or Mitsuba/Sionna
    XML (.xml, with --grid and --tx)."""
    variant: Literal["blueprint", "dynamic", "all", "moving"] = "all"
    """Which twin to build: blueprint (static objects), dynamic (blueprint + movable objects), all (both), or moving
    (people or vehicles moving through the scene: one table of snapshots in time, snapshot 0 traced in full and each
    later one re-traced differentially from the one before; the scene file's [moving] section; not part of all)."""
    rt: RTSettings = field(default_factory=RTSettings)
    """Ray-tracing settings."""
    per_path: bool = True
    """Also store the per-path table (every valid path of every cell with its interaction types)."""
    coverage_map: bool = True
    """Also render the RadioMapSolver coverage map (PNG with the obstacles drawn)."""
    coverage_samples: int = 2_000_000
    """Rays for the coverage map (none is rendered with --no-coverage-map, so then this has no effect)."""
    progress: bool = True
    """Show a progress bar."""
    osm: str | None = None
    """City scenes: where the footprints come from instead of the scene file's source: a GeoJSON or OpenStreetMap
    XML (.osm) file, or "osm" to download from OpenStreetMap (cached in the data root)."""
    cell_m: float | None = None
    """City and XML scenes: the grid's cell size in metres instead of the scene file's (smaller = finer, slower)."""
    grid: tuple[float, float, float, int, int] | None = None
    """XML scenes (sionna:munich, a .xml file): the grid as X0 Y0 CELL_M NX NY (centre of cell 0, 0; metres)."""
    tx: tuple[float, float, float] | None = None
    """XML scenes: the transmitter position X Y Z in metres."""
    executor: Literal["serial", "ray"] = "serial"
    """Where trace batches run: serial (this process, the default) or ray (Ray workers; `pip install 'dtradar[ray]'`).
    Both give the same table and version. A --differential re-trace always runs in this process."""
    ray_address: str | None = None
    """With --executor ray: an existing Ray cluster (HOST:PORT as `ray start --head` prints it, ray://HOST:10001, or
    auto; else $RAY_ADDRESS); default: a local Ray started for this build. A cluster that does not answer within
    seconds fails the build before anything is traced."""
    workers: int = 0
    """With --executor ray: Ray workers (one scene each); 0 = one per CPU of the cluster."""
    differential: bool = False
    """Dynamic twins: start from the newest stored blueprint built with the same settings (RT settings, grid,
    transmitter, library versions ...; any difference is refused before tracing, naming it) and re-trace only the
    cells whose radio features the changed objects can affect (see dtradar_data.pipeline.differential); the card
    records the parent version. With --variant all the blueprint is traced in full first and the dynamic twin
    re-traced from it; --variant blueprint is refused (a blueprint has no parent)."""
    retrace_radius_m: float = 1.0
    """With --differential or --variant moving (only): also re-trace cells within this distance of a changed object
    (a moved mover: its old and new place) or of its line of sight."""
    tx_pose_error: tuple[float, float] | None = None
    """OFFSET_M ANGLE_DEG: build the antenna-pose-error twin instead, its transmitter moved this far horizontally and
    its array turned this many degrees off its boresight (seeded by --tx-pose-seed; same pose for every variant),
    named <scene>-txpose (e.g. cubicle-txpose/blueprint); see dtradar_data.scenes.tx_pose."""
    tx_pose_seed: int = 0
    """With --tx-pose-error: the seed of the move's direction and of the turn's axis."""
    horizon_s: float | None = None
    """With --variant moving: how long the moving twin lasts, in seconds, instead of the scene file's horizon_s
    (default: the movers' common period); rounded to whole robot steps (the file's dt_s); past the period the movers
    go on walking. Part of the version."""

    def __post_init__(self) -> None:
        # the scene options as the command line checks them (NaN, infinity, sizes), for a config built in Python too
        check_scene_options(footprints=self.osm, cell_m=self.cell_m, grid=self.grid, tx=self.tx)
        if not math.isfinite(self.retrace_radius_m):
            raise InvalidSettingError(
                f"--retrace-radius-m {self.retrace_radius_m} must be a finite number", hint="e.g. --retrace-radius-m 3"
            )
        if self.coverage_samples < 1:
            raise InvalidSettingError(
                f"--coverage-samples {self.coverage_samples} must be positive",
                hint="the default is 2000000; use --no-coverage-map to skip the map",
            )
        if self.retrace_radius_m < 0:
            raise InvalidSettingError(
                f"--retrace-radius-m {self.retrace_radius_m} must be >= 0",
                hint="it is how far around a changed object cells are re-traced, in metres; e.g. 3",
            )
        if self.retrace_radius_m != BuildConfig.retrace_radius_m and not (
            self.differential or self.variant == MOVING_VARIANT
        ):
            raise InvalidSettingError(
                "--retrace-radius-m applies to --differential and --variant moving only",
                hint="add --differential, or drop it",
            )
        if self.variant == MOVING_VARIANT:
            self._check_moving()
        elif self.horizon_s is not None:
            raise InvalidSettingError(
                "--horizon-s applies to --variant moving only", hint="add --variant moving, or drop it"
            )
        if self.differential and self.variant == "blueprint":
            raise InvalidSettingError(
                "--differential applies to dynamic twins only: a blueprint has no parent to start from, it is always "
                "traced in full",
                hint="drop --differential, or build --variant dynamic (or all) with it",
            )
        if self.differential and self.variant == "dynamic" and self.executor == "ray":
            raise InvalidSettingError(
                "--executor ray does not apply to a --differential build of the dynamic twin: its few re-traced "
                "cells are traced in this process",
                hint="drop --executor ray (and --ray-address, --workers), or drop --differential to trace it on Ray",
            )
        if self.workers < 0:
            raise InvalidSettingError(
                f"--workers {self.workers} must be >= 0", hint="0 is one Ray worker per CPU; or give a count, e.g. 2"
            )
        if self.tx_pose_error is not None:
            if len(self.tx_pose_error) != 2:
                raise InvalidSettingError(
                    f"--tx-pose-error takes OFFSET_M ANGLE_DEG, got {self.tx_pose_error!r}", hint="e.g. 0.5 5"
                )
            check_tx_pose_error(*self.tx_pose_error, self.tx_pose_seed)
        elif self.tx_pose_seed != 0:
            raise InvalidSettingError(
                "--tx-pose-seed applies to --tx-pose-error only", hint="add --tx-pose-error 0.5 5"
            )
        if self.executor == "ray":
            import_ray()  # a missing Ray is a setup error, reported before anything is traced
        elif self.ray_address is not None or self.workers:
            raise InvalidSettingError(
                "--ray-address and --workers apply to --executor ray only", hint="add --executor ray, or drop them"
            )

    def _check_moving(self) -> None:
        """The options a moving twin's build refuses rather than ignores."""
        if self.horizon_s is not None and (not math.isfinite(self.horizon_s) or self.horizon_s <= 0):
            raise InvalidSettingError(
                f"--horizon-s {self.horizon_s} must be a finite number of seconds > 0",
                hint="e.g. --horizon-s 60, or drop it for the movers' common period",
            )
        if self.differential:
            raise InvalidSettingError(
                "--differential does not apply to --variant moving: a moving twin is always traced differentially, "
                "each snapshot from the one before (snapshot 0 in full)",
                hint="drop --differential (--retrace-radius-m still sets the radius)",
            )
        if self.tx_pose_error is not None:
            raise InvalidSettingError(
                "--tx-pose-error does not apply to --variant moving (no antenna-pose-error moving twin yet)",
                hint="drop --tx-pose-error, or build --variant blueprint / dynamic / all with it",
            )
        if not self.coverage_map or self.coverage_samples != BuildConfig.coverage_samples:
            raise InvalidSettingError(
                "--no-coverage-map and --coverage-samples do not apply to --variant moving: a moving twin has no "
                "coverage map (its card shows an animation of the traced table instead)",
                hint="drop them",
            )
        if self.grid is not None or self.tx is not None:
            raise InvalidSettingError(
                "--grid and --tx apply to XML scenes, and a scene built on an XML file has no moving twin",
                hint="drop --grid and --tx; moving twins are declared in a room or city scene file's [moving] section",
            )

    def check_scene(self, spec) -> None:
        """The checks that need the scene, run before anything is traced (see :meth:`RTSettings.check_scene`)."""
        self.rt.check_scene(spec)


def build_inputs(spec, config: BuildConfig, *, libraries: dict[str, str] | None = None) -> dict:
    """Everything that determines a dataset version's files; its hash is the version. ``libraries`` (default: the
    installed versions) lets a check recompute the version of a build made elsewhere.

    Besides the scene and the RT settings: whether the per-path table is stored, the coverage map's settings (it is
    one of the version's files), and for a city quadrant the specs its overview plot draws (the other quadrants)."""
    inputs = {
        **versions.build_inputs(spec.to_dict(), config.rt.hashed(), SCHEMA_VERSION, libraries),
        "per_path": config.per_path,
        "coverage": (
            {
                "solver": "sionna.rt.RadioMapSolver",
                "samples_per_tx": config.coverage_samples,
                "cells_per_grid_cell_side": COVERAGE_SUBCELLS,
            }
            if config.coverage_map
            else None
        ),
    }
    if spec.prisms and "city" in spec.provenance:
        inputs["city_overview"] = [s.digest() for s in city_quadrant_specs(spec, config)]
    return inputs


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
    size = batch_layout(len(points), settings)
    n_batches = max(1, -(-len(points) // size))
    if work_dir is not None:
        work_dir = batch_dir(work_dir, settings, size)
        work_dir.mkdir(parents=True, exist_ok=True)
    cell_parts, path_parts = [], []
    bar = tqdm(total=len(points), unit="cell", desc=f"ray tracing {spec.name}", disable=not progress)
    on_ray: set[int] = set()
    if executor == "ray":
        if work_dir is None:
            raise InvalidSettingError("--executor ray needs a work folder", hint="build through build()/build_one()")
        on_ray = {b for b in range(n_batches) if not batch_path(work_dir, b).exists()}
        trace_on_ray(
            spec,
            settings,
            points,
            ix,
            iy,
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
        if cache is not None and cache.exists():
            cells, paths = load_batch(cache)
        else:
            if tracer is None:
                tracer = RayTracer(spec, settings)
                tracer.check_points(points)  # the cheap check, once, before the first expensive trace
            cells, paths = trace_batch(tracer, points[sl], ix[sl], iy[sl], per_path=per_path)
            if cache is not None:
                save_batch(cache, cells, paths)
        cell_parts.append(cells)
        if per_path:
            path_parts.append(paths)
        if b not in on_ray:  # the Ray executor advanced the bar as its batches finished
            bar.update(len(points[sl]))
    bar.close()
    merged = {k: np.concatenate([c[k] for c in cell_parts]) for k in features.CELL_RADIO_KEYS}
    cells_tbl = features.cells_table(xs, ys, blocked, merged)
    paths_tbl = features.paths_table(path_parts) if per_path else None
    return cells_tbl, paths_tbl, blocked, tracer


def scene_config(config: BuildConfig, spec) -> BuildConfig:
    """``config`` with the scene's own RT defaults (a city's ``[rt]``) for every setting the user left at the
    RTSettings default; a value the user changed wins."""
    default = RTSettings()
    changes = {k: v for k, v in spec.rt_defaults.items() if getattr(config.rt, k) == getattr(default, k)}
    return dataclasses.replace(config, rt=dataclasses.replace(config.rt, **changes)) if changes else config


def build_one(spec, config: BuildConfig) -> Dataset:
    """Build (or reuse) one variant of one scene."""
    config = scene_config(config, spec)
    config.check_scene(spec)
    ds_id = DatasetId(spec.scene, spec.variant, None)
    name = format_id(ds_id)
    inputs = build_inputs(spec, config)
    parent = None
    if config.differential and spec.variant == "dynamic":
        parent, parent_spec = differential_parent(spec, config)
        inputs["differential"] = {
            "parent": parent.version,
            "rule": differential.RULE,
            "radius_m": config.retrace_radius_m,
        }
    version = versions.version_id(inputs)
    local.check_can_store(ds_id, version)  # a damaged version folder would otherwise fail only after tracing
    work_dir = work_root() / spec.scene / spec.variant / version
    work_dir.parent.mkdir(parents=True, exist_ok=True)
    # One build of a version at a time: a second process waits here, then finds the version built and reuses it
    # (without the lock, the first one's cleanup deleted the shared work folder under the second). The wait says
    # whom it waits for, and how far that build has come, on stderr.
    with waiting_lock(
        work_dir.parent / f"{version}.lock",
        f"building {name} version {version}" + (" (differential)" if parent is not None else ""),
        then="this build reuses that version",
        progress=lambda: _work_progress(work_dir, spec, config.rt),
    ):
        if local.version_exists(ds_id, version):
            print(f"{name}: version {version} already built, reusing it")
            return local.load(name, revision=version)
        if parent is not None:
            t0 = time.perf_counter()
            cells, paths, blocked, tracer, record = differential.differential_trace(
                parent,
                parent_spec,
                spec,
                config.rt,
                radius_m=config.retrace_radius_m,
                per_path=config.per_path,
                tracer_factory=lambda: RayTracer(spec, config.rt),
            )
            print(
                f"{name}: re-traced {record['retraced_cells']} of {record['free_cells']} free cells "
                f"(parent {record['parent']})"
            )
            return _store(
                spec,
                config,
                ds_id,
                version,
                inputs,
                work_dir,
                cells,
                paths,
                blocked,
                tracer,
                time.perf_counter() - t0,
                {"differential": record},
            )
        return _trace_and_store(spec, config, ds_id, version, inputs, work_dir)


def _work_progress(work_dir: Path, spec, settings: RTSettings) -> str:
    """How far the build holding a version's lock has come, from its work folder's finished batch files."""
    free = int((~occupancy(spec)).sum())
    size = batch_layout(free, settings)
    where = batch_dir(work_dir, settings, size)
    done = len(list(where.glob("batch_*.npz"))) if where.is_dir() else 0
    if not done:
        return "it has finished no trace batch yet"
    return f"it has finished {done} of {-(-free // size)} trace batches"


def differential_parent(spec, config: BuildConfig):
    """The stored blueprint a differential build of ``spec`` starts from (with its per-path table when
    ``config.per_path``), and its scene: see :func:`differential_parent_version`."""
    version = differential_parent_version(spec, config)
    parent = local.load(f"{spec.scene}/blueprint", revision=version, paths=config.per_path)
    recorded = parent.meta["scene_spec"]
    parent_spec = dataclasses.replace(spec, variant="blueprint", objects=tuple(Box(**o) for o in recorded["objects"]))
    return parent, parent_spec


def differential_parent_version(spec, config: BuildConfig) -> str:
    """The newest stored blueprint of ``spec``'s scene whose rows a differential build may keep: every input they
    depend on equals this build's (the scene but its objects, every hashed RT setting, the schema and library
    versions, the per-path table: :func:`differential.inherited_differences`), even if a newer one was built with
    other settings. Otherwise :class:`InvalidSettingError` naming what differs in the closest stored blueprint (the
    fewest differences; the newest of equals), before anything is traced; reads ``meta.json`` files only."""
    config = scene_config(config, spec)
    name = f"{spec.scene}/blueprint"
    how = (
        f"build {name} with this build's settings first (`python -m dtradar_data build --scene <the same scene> "
        "--variant blueprint` with the same --rt.* and scene flags; `--variant all --differential` does both), or "
        "drop --differential to trace the dynamic twin in full"
    )
    did = DatasetId(spec.scene, "blueprint", None)
    if not local.local_versions(did):  # a user's scene is not a known name: no "did you mean" another scene
        raise DatasetNotFoundError(
            f"--differential starts from a stored {name}, and none is in {data_root()}", hint=how
        )
    _, newest, _ = local.resolve(did)
    here = spec.to_dict()
    rt = config.rt.hashed()
    libraries = versions.library_versions()
    candidates = [newest] + [v for v in reversed(local.local_versions(did)) if v != newest]
    closest: tuple[str, list[str]] | None = None
    for version in candidates:
        vdir = version_dir(did.scene, did.variant, version)
        try:
            meta = local.read_meta(vdir)
        except CorruptDatasetError:
            if version == newest:
                raise
            continue
        differs = differential.inherited_differences(
            meta,
            here,
            rt,
            schema_version=SCHEMA_VERSION,
            libraries=libraries,
            per_path=config.per_path,
            parent_has_paths=(vdir / PATHS_FILE).is_file(),
        )
        if not differs:
            return version
        if closest is None or len(differs) < len(closest[1]):
            closest = (version, differs)
    assert closest is not None  # the newest one's meta.json was read, or its error raised
    version, differs = closest
    tag = versions.read_refs(refs_path(did.scene, did.variant)).tag_of(version)
    which = "the only one" if len(candidates) == 1 else "the newest" if version == newest else "the closest"
    raise InvalidSettingError(
        f"--differential: no stored {name} was built with the inputs whose rows {spec.name} would keep; "
        f"{which} of {len(candidates)}, {name}@{tag or version} ({version}), differs in: {'; '.join(differs)}",
        hint=how,
    )


def _trace_and_store(
    spec, config: BuildConfig, ds_id: DatasetId, version: str, inputs: dict, work_dir: Path
) -> Dataset:
    settings = config.rt
    t0 = time.perf_counter()
    cells, paths, blocked, tracer = trace_grid(
        spec,
        settings,
        work_dir,
        per_path=config.per_path,
        progress=config.progress,
        executor=config.executor,
        ray_address=config.ray_address,
        workers=config.workers,
    )
    trace_s = time.perf_counter() - t0
    return _store(spec, config, ds_id, version, inputs, work_dir, cells, paths, blocked, tracer, trace_s, {})


def _store(
    spec,
    config: BuildConfig,
    ds_id: DatasetId,
    version: str,
    inputs: dict,
    work_dir: Path,
    cells,
    paths,
    blocked,
    tracer,
    trace_s: float,
    extra_meta: dict,
) -> Dataset:
    """Render the coverage map and overview, write the version with its metadata, clean the work folder."""
    settings = config.rt
    name = format_id(ds_id)
    with tempfile.TemporaryDirectory(prefix="dtradar-build-") as tmp:
        extra = {}
        if config.coverage_map:
            if tracer is None:
                tracer = RayTracer(spec, settings)
            extra["coverage.png"] = render_coverage_png(
                spec, tracer, Path(tmp) / "coverage.png", samples=config.coverage_samples
            )
        if spec.prisms and "city" in spec.provenance:
            extra["city.png"] = save_city_overview_png(
                city_quadrant_specs(spec, config), Path(tmp) / "city.png", highlight=_original_scene(spec)
            )
        num_free = int((~blocked).sum())
        meta = {
            **_version_meta(spec, settings, name, version, inputs),
            **extra_meta,
            "build_inputs_hash": version,
            "stats": {
                "num_cells": int(blocked.size),
                "num_free": num_free,
                "num_with_paths": int(np.count_nonzero(cells.column("num_paths").to_numpy() > 0)),
                "num_paths_total": paths.num_rows if paths is not None else None,
                "trace_seconds": round(trace_s, 2),
                **(_retraced(work_dir, settings, num_free) if settings.batch_independent else {}),
            },
        }
        out = writing.write_version(ds_id, version, cells, meta, paths=paths, extra_files=extra)
    if tracer is not None:
        tracer.close()
    shutil.rmtree(work_dir, ignore_errors=True)
    print(f"{name}: stored version {version} in {out}")
    return local.load(name, revision=version)


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


def _version_meta(spec, settings: RTSettings, name: str, version: str, inputs: dict) -> dict:
    """The metadata every built version records about its scene, settings and libraries."""
    return {
        "name": name,
        "scene": spec.scene,
        "variant": spec.variant,
        "version": version,
        "schema_version": SCHEMA_VERSION,
        "title": spec.title,
        "description": spec.description,
        "scene_spec": spec.to_dict(),
        "scene_hash": spec.digest(),
        "rt": {
            **settings.hashed(),
            "reduction": REDUCTION_DOC,
            "solver": "sionna.rt.PathSolver",
            "mitsuba_variant": active_variant() or "(reused cached batches)",
        },
        "transmitter": spec.tx.to_dict(),
        "grid": spec.grid.to_dict(),
        "rx_height_m": spec.rx_height_m,
        "robot_height_m": spec.robot_height_m,
        "library_versions": inputs["library_versions"],
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "licence": spec.licence,
        "attribution": spec.attribution,
        "source": spec.source,
        **({"city": city} if (city := _provenance(spec)) else {}),
        **({"tx_pose_error": spec.provenance["tx_pose_error"]} if "tx_pose_error" in spec.provenance else {}),
    }


def _original_scene(spec) -> str:
    """The scene an antenna-pose-error twin was made from; ``spec.scene`` for any other twin."""
    return (spec.provenance.get("tx_pose_error") or {}).get("scene", spec.scene)


def _provenance(spec) -> dict:
    """What ``meta["city"]`` records: the scene's provenance without the pose error (recorded on its own)."""
    return {k: v for k, v in spec.provenance.items() if k != "tx_pose_error"}


def city_quadrant_specs(spec, config: BuildConfig) -> list:
    """The blueprint specs of every quadrant of ``spec``'s city (for the overview plot); a pose twin's quadrant
    carries the twin's transmitter."""
    city = spec.provenance["city"]
    specs = [
        load_scene_spec(s, "blueprint", footprints=config.osm, cell_m=config.cell_m)
        for s, _ in build_targets(city, "blueprint")
    ]
    if _original_scene(spec) == spec.scene:
        return specs
    return [dataclasses.replace(q, tx=spec.tx) if q.scene == _original_scene(spec) else q for q in specs]


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


def build(config: BuildConfig) -> list[Dataset]:
    """Build the requested variant(s) of ``config.scene``; returns the stored datasets.

    Everything that can refuse the build is checked before the first variant is traced, so `all` does not fail
    after the blueprint and a refused build changes nothing on disk: each variant's scene and resources, that
    ``--differential`` has a dynamic twin to apply to and a stored parent with the same inputs (unless this build
    traces that blueprint first), and that a ``--ray-address`` cluster answers. ``--variant moving``:
    :func:`build_moving`."""
    if config.variant == MOVING_VARIANT:
        return build_moving(config)
    specs = build_specs(config)
    if config.differential:
        dynamic = [s for s in specs if s.variant == "dynamic"]
        if not dynamic:
            raise InvalidSettingError(
                f"--differential applies to dynamic twins, and {config.scene} has none to build "
                f"(this build traces {', '.join(s.name for s in specs)} in full)",
                hint="drop --differential",
            )
        traced_first = {s.scene for s in specs if s.variant == "blueprint"}
        for spec in dynamic:
            if spec.scene not in traced_first:
                differential_parent_version(spec, config)
    for spec in specs:
        scene_config(config, spec).check_scene(spec)
        cfg = scene_config(config, spec)
        check_resources(spec.name, int((~occupancy(spec)).sum()), cfg.rt, work_root(), per_path=cfg.per_path)
    if config.executor == "ray" and not (config.differential and all(s.variant == "dynamic" for s in specs)):
        check_ray_address(config.ray_address)
    with executor_session(config):
        return [build_one(spec, config) for spec in specs]


def executor_session(config: BuildConfig):
    """The context a build's scenes are traced in: with ``--executor ray`` one :class:`RaySession` for all of them
    (Ray started once, its workers warm from one scene to the next), else nothing."""
    if config.executor == "ray":
        return RaySession(config.ray_address, config.workers)
    return contextlib.nullcontext()


# ------------------------------------------------------------------------------------------- moving twins
def moving_build_inputs(moving_scene, config: BuildConfig, *, libraries: dict[str, str] | None = None) -> dict:
    """Everything that determines a moving twin's files; its hash is the version: the moving scene (its base's
    digest, the movers, the step and the number of snapshots), the RT settings, both schema versions, the library
    versions, the per-path table, and the differential rule and radius each snapshot after the first is traced
    with. No coverage map is rendered (the animation is drawn from the table)."""
    return {
        **versions.build_inputs(moving_scene.to_dict(), config.rt.hashed(), SCHEMA_VERSION, libraries),
        "moving_schema_version": MOVING_SCHEMA_VERSION,
        "moving_digest": moving_scene.digest(),
        "per_path": config.per_path,
        "coverage": None,
        "differential": {
            "rule": differential.RULE,
            "radius_m": max(config.retrace_radius_m, moving_scene.base.grid.cell_m),
        },
    }


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
    :data:`~dtradar_data.scenes.movers.MAX_SNAPSHOTS`, else :class:`InvalidSettingError` saying which horizon fits."""
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


def build_moving(config: BuildConfig, *, snapshots: int | None = None) -> list[Dataset]:
    """Build (or reuse) the moving twin(s) of ``config.scene``: every check (scene, resources, Ray cluster) before
    the first trace. ``snapshots`` (tests, quick looks): only the first this many snapshots (a twin of its own:
    its scene says so, so it has its own version)."""
    scenes = moving_scenes(config)
    if snapshots is not None:
        scenes = [
            dataclasses.replace(
                m,
                snapshots=min(snapshots, m.snapshots),
                provenance={**m.provenance, "snapshots": min(snapshots, m.snapshots), "horizon_from": "cut short"},
            )
            for m in scenes
        ]
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


def build_moving_one(moving_scene, config: BuildConfig) -> Dataset:
    """Build (or reuse) one moving twin: snapshot by snapshot, resumable (:mod:`.moving`), then one version."""
    config = scene_config(config, moving_scene.base)
    spec0 = moving_scene.spec_at(0)
    config.check_scene(spec0)
    ds_id = DatasetId(moving_scene.scene, MOVING_VARIANT, None)
    name = format_id(ds_id)
    inputs = moving_build_inputs(moving_scene, config)
    version = versions.version_id(inputs)
    local.check_can_store(ds_id, version)
    work_dir = work_root() / moving_scene.scene / MOVING_VARIANT / version
    work_dir.parent.mkdir(parents=True, exist_ok=True)
    with waiting_lock(
        work_dir.parent / f"{version}.lock",
        f"building {name} version {version}",
        then="this build reuses that version",
        progress=lambda: moving.work_progress(work_dir, moving_scene.snapshots),
    ):
        if local.version_exists(ds_id, version):
            print(f"{name}: version {version} already built, reusing it")
            return local.load(name, revision=version)

        def full_trace(spec, batch_dir: Path):
            return trace_grid(
                spec,
                config.rt,
                batch_dir,
                per_path=config.per_path,
                progress=config.progress,
                executor=config.executor,
                ray_address=config.ray_address,
                workers=config.workers,
            )

        t0 = time.perf_counter()
        snaps = moving.trace_snapshots(
            moving_scene,
            config.rt,
            work_dir,
            radius_m=config.retrace_radius_m,
            per_path=config.per_path,
            full_trace=full_trace,
            progress=config.progress,
        )
        trace_s = time.perf_counter() - t0
        cells, paths = moving.moving_tables(moving_scene, snaps)
        record = moving.build_record(moving_scene, snaps, radius_m=config.retrace_radius_m)
        free = sum(s.record["free_cells"] for s in snaps)
        meta = {
            **_version_meta(moving_scene.base, config.rt, name, version, inputs),
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
            "moving_build": record,
            "build_inputs_hash": version,
            "stats": {
                "num_cells": cells.num_rows,
                "num_free": free,
                "num_with_paths": int(np.count_nonzero(cells.column("num_paths").to_numpy() > 0)),
                "num_paths_total": paths.num_rows if paths is not None else None,
                "trace_seconds": round(trace_s, 2),
                "snapshots": moving_scene.snapshots,
                "cells_per_snapshot": spec0.grid.nx * spec0.grid.ny,
            },
        }
        with tempfile.TemporaryDirectory(prefix="dtradar-build-") as tmp:
            gif = moving.render_gif(moving_scene, cells, Path(tmp) / moving.GIF_FILE)
            out = writing.write_version(ds_id, version, cells, meta, paths=paths, extra_files={moving.GIF_FILE: gif})
        shutil.rmtree(work_dir, ignore_errors=True)
        print(f"{name}: stored version {version} in {out}")
        return local.load(name, revision=version)
