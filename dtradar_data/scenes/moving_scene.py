"""The moving twin: a base scene plus its movers, as a series of static scenes one robot step apart.

A :class:`MovingScene` is a base scene (the blueprint's objects, or the dynamic twin's) plus its movers
(:class:`~dtradar_data.scenes.mover.Mover`), sampled every ``dt_s`` seconds, the time one robot step takes, for
``snapshots`` steps. Snapshot ``k`` is a plain static scene (:meth:`MovingScene.spec_at`), so the existing
ray-tracing pipeline traces any of them as it traces a blueprint; :meth:`MovingScene.changed_between` lists the mover
boxes whose place changed between two snapshots, the objects a differential re-trace starts from. Scene files declare
movers in a ``[moving]`` section that only the variant ``"moving"`` reads
(:func:`~dtradar_data.scenes.moving_section.moving_scene_from_section`): the blueprint and dynamic twins of a file
never see it, so their digests do not change when movers are added. The defaults (:data:`ROBOT_SPEED_MPS`,
:data:`DEFAULT_MAX_SNAPSHOTS`, :data:`MAX_SNAPSHOTS`) and the validation rules are in ``docs/reference/scene-files.md``
("Movers and moving twins").

Every mistake is a :class:`~dtradar_data.core.errors.SceneFileError` that names the mover and says what to change:
a waypoint outside the grid, a path whose box would run into a wall, an obstacle or a building (the whole segment
between two waypoints is checked, not only its ends), duplicate names, a name an object of the scene already has, a
step that is not > 0, a horizon of too many snapshots.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from shapely.geometry import Point, Polygon

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.model import Box, SceneSpec
from dtradar_data.scenes.mover import Mover, is_finite, mover_error, point_text

__all__ = [
    "BASE_VARIANTS",
    "DEFAULT_MAX_SNAPSHOTS",
    "MAX_SNAPSHOTS",
    "MOVING_VARIANT",
    "ROBOT_SPEED_MPS",
    "MoverChange",
    "MovingScene",
    "common_snapshots",
]

#: The variant name of a moving twin (``cubicle/moving``), built by :mod:`dtradar_data.pipeline.moving`; a dataset
#: variant (:data:`dtradar_data.core.ids.DATASET_VARIANTS`) apart from the static pair ``blueprint``/``dynamic``.
MOVING_VARIANT = "moving"
#: The variants a moving twin can start from: the blueprint's objects (the default) or the dynamic twin's.
BASE_VARIANTS = ("blueprint", "dynamic")
#: The robot's speed behind the default step: the agent moves one cell per step, so one step takes
#: ``cell_m / ROBOT_SPEED_MPS`` seconds. 0.5 m/s is the usual safe speed of an indoor service robot among people
#: (a TurtleBot 2 tops out at 0.7 m/s): 1 s per step in the cubicle lab (0.5 m cells), 0.5 s in the meeting room.
ROBOT_SPEED_MPS = 0.5
#: The default horizon is the movers' common period in whole snapshots, but at most this many: each snapshot is one
#: full-scene trace for the builder, so movers whose periods share no factor must not ask for thousands by default.
DEFAULT_MAX_SNAPSHOTS = 500
#: The most snapshots a moving twin may have (a file's ``horizon_s`` included): thousands of traces of one scene are
#: hours even on a GPU, and never what a mistyped horizon meant.
MAX_SNAPSHOTS = 2000
#: Objects wholly below this height never block a mover (rugs, road surfaces): the occupancy grid's rule
#: (:data:`dtradar_data.geometry.occupancy.OCCUPANCY_FLOOR_CLEARANCE_M`).
FLOOR_CLEARANCE_M = 0.05
_EPS = 1e-6  # metres: tolerance of the "inside the grid" check (TOML decimals are not exact in binary)
_AREA_EPS = 1e-6  # square metres: a path that merely touches an obstacle does not run into it


def common_snapshots(movers: Sequence[Mover], dt_s: float, cap: int = DEFAULT_MAX_SNAPSHOTS) -> int:
    """The movers' common period in snapshots: the least common multiple of each period rounded to whole steps
    (at least 1), at most ``cap``. When every period is a whole number of steps the last snapshot runs seamlessly
    into the first; otherwise, or when capped, the movers jump a little at the wrap."""
    n = 1
    for m in movers:
        n = math.lcm(n, max(1, round(m.period_s / dt_s)))
        if n >= cap:
            return cap
    return n


@dataclass(frozen=True)
class MoverChange:
    """One mover whose box differs between two snapshots: where it was, where it is (same name)."""

    before: Box
    after: Box

    @property
    def name(self) -> str:
        return self.after.name


@dataclass(frozen=True)
class MovingScene:
    """A base scene plus movers, sampled every ``dt_s`` seconds at snapshots ``k = 0 .. snapshots - 1``.

    ``base`` is the variant the movers move through, exactly as its own reader builds it (its digest is that
    variant's digest). Checked when made: at least one mover, unique names that no object of the base has, every
    waypoint inside the grid, every path clear of the base's walls, obstacles and buildings (see
    :meth:`check_paths`), a step > 0 and 1 to :data:`MAX_SNAPSHOTS` snapshots."""

    base: SceneSpec
    movers: tuple[Mover, ...]
    dt_s: float
    snapshots: int
    title: str = ""
    description: str = ""
    provenance: dict[str, Any] = field(default_factory=dict, compare=False)
    """How the step and horizon were chosen and where the base came from; not in the digest."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "movers", tuple(self.movers))
        if not self.title:
            object.__setattr__(self, "title", f"{self.base.title} (moving twin)")
        if not self.description:
            object.__setattr__(self, "description", self.base.description)
        if not self.movers:
            raise SceneFileError(
                f"{self.name} has no movers", hint="add at least one [[moving.mover]] table to the [moving] section"
            )
        if not is_finite(self.dt_s) or self.dt_s <= 0:
            raise SceneFileError(
                f"dt_s = {self.dt_s!r} must be a finite number of seconds > 0 (the time one robot step takes)",
                hint=f"drop dt_s for the default cell_m / {ROBOT_SPEED_MPS} m/s, or give e.g. dt_s = 1.0",
            )
        if isinstance(self.snapshots, bool) or not isinstance(self.snapshots, int) or self.snapshots < 1:
            raise SceneFileError(
                f"{self.name}: {self.snapshots!r} snapshots: a moving twin needs at least one",
                hint="give horizon_s of at least one step (dt_s), or drop it for the movers' common period",
            )
        if self.snapshots > MAX_SNAPSHOTS:
            raise SceneFileError(
                f"{self.name}: a horizon of {self.snapshots * self.dt_s:g} s at dt_s = {self.dt_s:g} s makes "
                f"{self.snapshots} snapshots, more than the {MAX_SNAPSHOTS} a moving twin may have (each is one "
                "full-scene trace)",
                hint=f"shorten horizon_s to at most {MAX_SNAPSHOTS * self.dt_s:g} s, or lengthen dt_s",
            )
        self.check_names()
        self.check_paths()

    # -- identity
    @property
    def scene(self) -> str:
        return self.base.scene

    @property
    def variant(self) -> str:
        return MOVING_VARIANT

    @property
    def name(self) -> str:
        return f"{self.scene}/{MOVING_VARIANT}"

    @property
    def horizon_s(self) -> float:
        return self.snapshots * self.dt_s

    # -- checks
    def check_names(self) -> None:
        """Unique mover names, none an object's or building's name of the base (the meshes are named after them)."""
        taken = {b.name: "an object" for b in self.base.objects} | {p.name: f"a {p.kind}" for p in self.base.prisms}
        seen: set[str] = set()
        for m in self.movers:
            if m.name in seen:
                raise mover_error(
                    m.name, "two movers have this name", "give every mover a unique name (e.g. 'walker_02')"
                )
            seen.add(m.name)
            if m.name in taken:
                raise mover_error(
                    m.name,
                    f"the {self.base.variant} already has {taken[m.name]} named {m.name!r}",
                    "rename the mover: a mover's name may not be an object's of the scene it moves through",
                )

    def check_paths(self) -> None:
        """Every waypoint inside the grid, the mover no taller than the room, and the ground its box sweeps along
        each segment (:meth:`Mover.swept_footprint`) clear of every wall, obstacle and building it would hit: the
        boxes and prisms that reach into ``[5 cm, mover's height]`` (the occupancy grid's rule: rugs and road
        surfaces do not count). Exact polygon overlap with shapely, so a path that cuts the corner of a table
        between two free waypoints fails too; touching is allowed."""
        xmin, ymin, xmax, ymax = self.base.grid.bounds()
        room = self.base.room
        for m in self.movers:
            for i, (x, y) in enumerate(m.waypoints):
                if not (xmin - _EPS <= x <= xmax + _EPS and ymin - _EPS <= y <= ymax + _EPS):
                    raise mover_error(
                        m.name,
                        f"waypoints[{i}] {point_text((x, y))} is outside the grid "
                        f"[{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}] m",
                        "move the waypoint onto the grid: movers walk where the robot can be",
                    )
            if room is not None and m.height_m > room.height_m + _EPS:
                raise mover_error(
                    m.name,
                    f"height_m = {m.height_m:g} is taller than the room ({room.height_m:g} m)",
                    "lower height_m below the ceiling",
                )
            obstacles = _obstacles(self.base, m.height_m)
            tx = self.base.tx.position_m
            for start, end, i, j in m.segments():
                swept = m.swept_footprint(start, end)
                if m.height_m >= tx[2] and swept.covers(Point(tx[0], tx[1])):  # the mover's box would hold it
                    raise mover_error(
                        m.name,
                        f"the path from waypoints[{i}] {point_text(start)} to waypoints[{j}] {point_text(end)} runs "
                        f"through the transmitter at ({tx[0]:g}, {tx[1]:g}, {tx[2]:g}) m, which its "
                        f"{m.height_m:g} m box would cover",
                        "route the mover round the transmitter, or lower height_m below the transmitter",
                    )
                for label, poly in obstacles:
                    if not swept.intersects(poly) or swept.intersection(poly).area <= _AREA_EPS:
                        continue
                    inside = next((k for k, p in ((i, start), (j, end)) if _inside(p, poly)), None)
                    if inside is not None:
                        problem = f"waypoints[{inside}] {point_text(m.waypoints[inside])} is inside {label}"
                    else:
                        hit = swept.intersection(poly).representative_point()
                        problem = (
                            f"the path from waypoints[{i}] {point_text(start)} to waypoints[{j}] {point_text(end)} "
                            f"runs into {label} near ({hit.x:.2f}, {hit.y:.2f})"
                        )
                    raise mover_error(
                        m.name,
                        problem + f" (its box is {m.width_m:g} m along its way, {m.length_m:g} m across)",
                        "move the waypoints so that the path keeps clear of it (add a waypoint to go round), or "
                        "make the mover smaller",
                    )

    # -- snapshots
    def _index(self, k: int) -> int:
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < self.snapshots:
            raise SceneFileError(
                f"{self.name} has no snapshot {k!r}: it has {self.snapshots} (k = 0 .. {self.snapshots - 1}, one "
                f"every {self.dt_s:g} s)",
                hint=f"use an integer k from 0 to {self.snapshots - 1}; the movers repeat every {self.snapshots} "
                "snapshots when that is their common period (k % snapshots)",
            )
        return k

    def time_s(self, k: int) -> float:
        """The time of snapshot ``k``: ``k * dt_s`` seconds."""
        return self._index(k) * self.dt_s

    def boxes_at(self, k: int) -> tuple[Box, ...]:
        """Every mover as a :class:`Box` at snapshot ``k``, in the order of :attr:`movers`."""
        t = self.time_s(k)
        return tuple(m.box_at(t) for m in self.movers)

    def spec_at(self, k: int) -> SceneSpec:
        """Snapshot ``k`` as a plain static :class:`SceneSpec` (variant ``"moving"``): the base's objects, then every
        mover as a box at ``k * dt_s``; grid, transmitter, prisms and room are the base's. Trace it like any twin."""
        t = self.time_s(k)
        provenance = {**self.base.provenance, "moving": {**self.provenance, "snapshot": k, "t_s": t}}
        return replace(
            self.base,
            variant=MOVING_VARIANT,
            title=self.title,
            description=self.description,
            objects=self.base.objects + self.boxes_at(k),
            provenance=provenance,
        )

    def changed_between(self, k0: int, k1: int) -> tuple[MoverChange, ...]:
        """The movers whose box (place or heading) differs between snapshots ``k0`` and ``k1``, with both boxes: what
        a differential re-trace from ``spec_at(k0)`` to ``spec_at(k1)`` has to look at. Nothing else changes."""
        pairs = zip(self.boxes_at(k0), self.boxes_at(k1))
        return tuple(MoverChange(before, after) for before, after in pairs if before != after)

    # -- identity
    def to_dict(self) -> dict[str, Any]:
        """JSON-able and canonical: the base by its digest, the movers, the step and the number of snapshots."""
        return {
            "scene": self.scene,
            "variant": MOVING_VARIANT,
            "base": {"variant": self.base.variant, "digest": self.base.digest()},
            "movers": [m.to_dict() for m in self.movers],
            "dt_s": self.dt_s,
            "snapshots": self.snapshots,
        }

    def canonical_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)

    def digest(self) -> str:
        """sha256 hex of the canonical JSON: the base's digest, the movers, ``dt_s`` and the number of snapshots."""
        return hashlib.sha256(self.canonical_json().encode("ascii")).hexdigest()


def _obstacles(spec: SceneSpec, height_m: float) -> list[tuple[str, Polygon]]:
    """``(label, footprint)`` of what a mover of ``height_m`` standing on the floor would run into."""
    out = []
    for b in spec.obstacles():
        if b.z_m < height_m and b.top_m > FLOOR_CLEARANCE_M:
            out.append((f"{b.kind} {b.name!r}", Polygon(b.corners())))
    for p in spec.prisms:
        if p.z_m < height_m and p.top_m > FLOOR_CLEARANCE_M:
            out.append((f"{p.kind} {p.name!r}", Polygon(p.exterior, p.holes)))
    return out


def _inside(p: tuple[float, float], poly: Polygon) -> bool:
    """Whether the waypoint itself (the mover's centre) is inside the obstacle's footprint (not on its edge)."""
    return poly.contains(Point(p))
