"""What a build is asked for: :class:`BuildConfig` (the ``build`` command's flags, tyro reads the field docstrings
as their help) and its cross-flag checks, and :func:`scene_config`, which fills in a scene's own RT defaults.

Every check that needs no scene runs when the config is made (from the command line or in Python), so a refused
flag combination fails before any scene file, footprint or mesh is read.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.ids import MOVING_VARIANT
from dtradar_data.core.ray_cluster import check_address_given
from dtradar_data.pipeline.executors import import_ray
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes.options import check_scene_options
from dtradar_data.scenes.tx_pose import check_tx_pose_error


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
            check_address_given(self.ray_address)  # "" would start a local Ray, as no --ray-address does
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


def scene_config(config: BuildConfig, spec) -> BuildConfig:
    """``config`` with the scene's own RT defaults (a city's ``[rt]``) for every setting the user left at the
    RTSettings default; a value the user changed wins."""
    default = RTSettings()
    changes = {k: v for k, v in spec.rt_defaults.items() if getattr(config.rt, k) == getattr(default, k)}
    return dataclasses.replace(config, rt=dataclasses.replace(config.rt, **changes)) if changes else config
