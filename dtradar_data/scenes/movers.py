"""Movers and moving twins: people walking and vehicles driving through a frozen scene, as a series of static scenes.

A twin is frozen (:class:`~dtradar_data.scenes.model.SceneSpec`); a real room or street is not. A :class:`Mover` is
one thing that moves: a person walking along waypoints indoors (about 1 m/s), a car or a bus driving along a lane
in a city (a few m/s), at constant speed along the polyline of its waypoints, round a ``"loop"`` (back to the first
waypoint) or ``"back-and-forth"``. At any time it is a :class:`Box` of the existing model (:meth:`Mover.box_at`)
whose local x points where it goes, so Sionna's car mesh, which faces local x, drives forwards.

A :class:`MovingScene` is a base scene (the blueprint's objects, or the dynamic twin's) plus its movers, sampled
every ``dt_s`` seconds, the time one robot step takes, for ``snapshots`` steps. Snapshot ``k`` is a plain static
scene (:meth:`MovingScene.spec_at`), so the existing ray-tracing pipeline traces any of them as it traces a blueprint;
:meth:`MovingScene.changed_between` lists the mover boxes whose place changed between two snapshots, the objects a
differential re-trace starts from. Scene files declare movers in a ``[moving]`` section that only the variant
``"moving"`` reads (:func:`moving_scene_from_section`): the blueprint and dynamic twins of a file never see it, so
their digests do not change when movers are added. The defaults (:data:`ROBOT_SPEED_MPS`,
:data:`DEFAULT_MAX_SNAPSHOTS`, :data:`MAX_SNAPSHOTS`) and the validation rules are in ``docs/scenes.md``
("Movers and moving twins").

Every mistake is a :class:`~dtradar_data.core.errors.SceneFileError` that names the mover and says what to change:
too few waypoints, non-finite or non-positive sizes and speeds, a waypoint outside the grid, a path whose box would
run into a wall, an obstacle or a building (the whole segment between two waypoints is checked, not only its ends),
duplicate names, a name an object of the scene already has, a step that is not > 0, a horizon of too many snapshots.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Annotated, Any

from pydantic import BeforeValidator, ValidationError
from shapely.geometry import Point, Polygon

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.city.streets import VEHICLES
from dtradar_data.scenes.fields import (
    Material,
    ObjName,
    SceneFileModel,
    Text,
    choice,
    fail,
)
from dtradar_data.scenes.materials import ITU_MATERIALS
from dtradar_data.scenes.model import Box, SceneSpec

__all__ = [
    "BASE_VARIANTS",
    "DEFAULT_MAX_SNAPSHOTS",
    "MAX_SNAPSHOTS",
    "MODES",
    "MOVER_KINDS",
    "MOVER_MESHES",
    "MOVING_VARIANT",
    "ROBOT_SPEED_MPS",
    "Mover",
    "MoverChange",
    "MovingScene",
    "common_snapshots",
    "moving_scene_from_section",
]

#: The variant name of a moving twin (``cubicle/moving``), built by :mod:`dtradar_data.pipeline.moving`; a dataset
#: variant (:data:`dtradar_data.core.ids.DATASET_VARIANTS`) apart from the static pair ``blueprint``/``dynamic``.
MOVING_VARIANT = "moving"
#: The variants a moving twin can start from: the blueprint's objects (the default) or the dynamic twin's.
BASE_VARIANTS = ("blueprint", "dynamic")
MODES = ("loop", "back-and-forth")
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
#: Meshes a mover may be drawn with: the keys of :data:`dtradar_data.geometry.meshes.BUNDLED_MESHES` (a test keeps
#: the two equal; scenes sit below geometry and cannot import it).
MOVER_MESHES = ("sionna:low_poly_car",)
#: Default size and look of a mover of a known kind: (width_m along its direction of travel, length_m across it,
#: height_m, material, mesh). A person as the dynamic twins' people (0.3 m chest to back, 0.5 m shoulders, 1.75 m,
#: ITU "wet_ground" standing in for tissue: cubicle.toml says why); cars and buses as the dynamic city twin's.
MOVER_KINDS: dict[str, tuple[float, float, float, str, str | None]] = {
    "person": (0.3, 0.5, 1.75, "wet_ground", None),
    **VEHICLES,  # (length, width, ...): a vehicle's length is along its way, its box's width_m
}
#: Objects wholly below this height never block a mover (rugs, road surfaces): the occupancy grid's rule
#: (:data:`dtradar_data.geometry.occupancy.OCCUPANCY_FLOOR_CLEARANCE_M`).
FLOOR_CLEARANCE_M = 0.05
_EPS = 1e-6  # metres: tolerance of the "inside the grid" check (TOML decimals are not exact in binary)
_AREA_EPS = 1e-6  # square metres: a path that merely touches an obstacle does not run into it
_CORNER_EPS = 1e-9  # metres: a mover this close to a waypoint is on the next segment (its heading turns there)


def _error(mover: str, problem: str, hint: str) -> SceneFileError:
    return SceneFileError(f"mover {mover!r}: {problem}", hint=hint)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _xy(p: tuple[float, float]) -> str:
    return f"({p[0]:g}, {p[1]:g})"


# ------------------------------------------------------------------------------------------- one mover
@dataclass(frozen=True)
class Mover:
    """One thing that moves at ``speed_mps`` along ``waypoints`` (scene metres): round a ``"loop"`` (from the last
    waypoint back to the first) or ``"back-and-forth"`` (to the last waypoint and back the same way), starting
    ``start_offset_s`` seconds into its route at t = 0. As a :class:`Box`: ``width_m`` along its direction of travel
    (local x), ``length_m`` across it, ``height_m`` up from the floor; ``mesh`` (a bundled mesh such as
    ``"sionna:low_poly_car"``) draws it scaled into that box, as :attr:`Box.mesh` does."""

    name: str
    kind: str
    material: str
    width_m: float
    length_m: float
    height_m: float
    speed_mps: float
    waypoints: tuple[tuple[float, float], ...]
    mode: str = "loop"
    start_offset_s: float = 0.0
    mesh: str | None = None

    def __post_init__(self) -> None:
        name = self.name
        if not isinstance(name, str) or not name:
            raise SceneFileError(
                f"a mover has no name ({name!r})", hint="give every mover a unique name, e.g. 'walker_01'"
            )
        for key in ("kind", "material"):
            if not isinstance(getattr(self, key), str) or not getattr(self, key):
                raise _error(name, f"{key} {getattr(self, key)!r} is not a name", f"give {key}, e.g. kind = 'person'")
        if self.material not in ITU_MATERIALS:
            close = did_you_mean(self.material, ITU_MATERIALS)
            raise _error(
                name,
                f"material {self.material!r} is not an ITU material" + (f"; {close}" if close else ""),
                "use one of: " + ", ".join(ITU_MATERIALS),
            )
        for key in ("width_m", "length_m", "height_m", "speed_mps"):
            value = getattr(self, key)
            if not _finite(value) or value <= 0:
                unit = "m/s, e.g. speed_mps = 1.0 for a walk" if key == "speed_mps" else "metres"
                raise _error(name, f"{key} = {value!r} must be a finite number > 0", f"give {key} in {unit}")
        if not _finite(self.start_offset_s):
            raise _error(
                name,
                f"start_offset_s = {self.start_offset_s!r} must be a finite number",
                "give the seconds into its route the mover is at t = 0, e.g. 0",
            )
        if self.mode not in MODES:
            close = did_you_mean(str(self.mode), MODES)
            raise _error(
                name,
                f"mode {self.mode!r} is not a mode" + (f"; {close}" if close else ""),
                "use 'loop' or 'back-and-forth'",
            )
        if self.mesh is not None and self.mesh not in MOVER_MESHES:
            close = did_you_mean(str(self.mesh), MOVER_MESHES)
            raise _error(
                name,
                f"mesh {self.mesh!r} is not a bundled mesh" + (f"; {close}" if close else ""),
                "use one of: " + ", ".join(MOVER_MESHES) + ", or drop mesh to draw the box itself",
            )
        points = self.waypoints
        if not isinstance(points, (list, tuple)) or len(points) < 2:
            count = len(points) if isinstance(points, (list, tuple)) else points
            raise _error(
                name,
                f"needs at least 2 waypoints, has {count!r}",
                "give waypoints = [[x0, y0], [x1, y1], ...] in scene metres (2 or more)",
            )
        clean = []
        for i, p in enumerate(points):
            if not (isinstance(p, (list, tuple)) and len(p) == 2 and all(_finite(v) for v in p)):
                raise _error(name, f"waypoints[{i}] = {p!r} is not a point", "write each waypoint as [x, y] in metres")
            clean.append((float(p[0]) + 0.0, float(p[1]) + 0.0))
        object.__setattr__(self, "waypoints", tuple(clean))
        for i in range(len(clean) - 1):
            if clean[i] == clean[i + 1]:
                raise _error(
                    name,
                    f"waypoints[{i}] and waypoints[{i + 1}] are the same point {_xy(clean[i])}",
                    "drop the repeated waypoint: a mover has no heading on a path of length 0",
                )
        if self.mode == "loop" and len(clean) > 2 and clean[0] == clean[-1]:
            raise _error(
                name,
                f"the last waypoint repeats the first {_xy(clean[0])}",
                "drop the last waypoint: mode = 'loop' goes back to the first one by itself",
            )

    # -- the route
    @property
    def route(self) -> tuple[tuple[float, float], ...]:
        """The points the mover passes in one period, first point repeated at the end: the waypoints and the first
        again (loop), or the waypoints and back again (back-and-forth)."""
        points = list(self.waypoints)
        if self.mode == "loop":
            return tuple(points + [points[0]])
        return tuple(points + points[-2::-1])

    def segments(self) -> list[tuple[tuple[float, float], tuple[float, float], int, int]]:
        """``(start, end, i, j)`` for each stretch of path between two waypoints (indices ``i``, ``j`` into
        :attr:`waypoints`), each once: a back-and-forth mover walks each twice, a loop also last to first."""
        n = len(self.waypoints)
        pairs = [(i, i + 1) for i in range(n - 1)]
        if self.mode == "loop" and n > 2:
            pairs.append((n - 1, 0))
        return [(self.waypoints[i], self.waypoints[j], i, j) for i, j in pairs]

    @property
    def path_length_m(self) -> float:
        """Length of one period's route in metres (a back-and-forth route counts its path twice)."""
        r = self.route
        return sum(math.dist(r[i], r[i + 1]) for i in range(len(r) - 1))

    @property
    def period_s(self) -> float:
        """Seconds until the mover is back where it started, heading the same way: route length / speed."""
        return self.path_length_m / self.speed_mps

    # -- kinematics
    def position_at(self, t_s: float) -> tuple[float, float, float]:
        """``(x, y, yaw_deg)`` at time ``t_s``: constant speed along the route, heading (degrees counter-clockwise
        from +x, in [0, 360)) along the current segment; on a waypoint it already faces the next segment."""
        if not _finite(t_s):
            raise _error(self.name, f"time {t_s!r} is not a finite number of seconds", "give t_s in seconds, e.g. 0.0")
        r = self.route
        total = self.path_length_m
        s = ((t_s + self.start_offset_s) * self.speed_mps) % total
        if s >= total:  # a tiny negative product rounds up to the period itself
            s = 0.0
        for i in range(len(r) - 1):
            (x0, y0), (x1, y1) = r[i], r[i + 1]
            seg = math.dist(r[i], r[i + 1])
            if s < seg - _CORNER_EPS or i == len(r) - 2:
                f = min(max(s / seg, 0.0), 1.0)
                yaw = math.degrees(math.atan2(y1 - y0, x1 - x0)) % 360.0
                return x0 + f * (x1 - x0), y0 + f * (y1 - y0), yaw
            s = max(s - seg, 0.0)
        raise AssertionError("unreachable: the last segment always returns")  # pragma: no cover

    def box_at(self, t_s: float) -> Box:
        """The mover at ``t_s`` as a :class:`Box` named after it: centre at its position (0.1 mm, the precision the
        scene's digest sees), yaw along its heading (0.001 degrees), standing on the floor."""
        x, y, yaw = self.position_at(t_s)
        yaw = round(yaw, 3) % 360.0
        return Box(
            name=self.name,
            kind=self.kind,
            material=self.material,
            x_m=round(x, 4) + 0.0,
            y_m=round(y, 4) + 0.0,
            width_m=self.width_m,
            length_m=self.length_m,
            height_m=self.height_m,
            z_m=0.0,
            yaw_deg=yaw + 0.0,
            mesh=self.mesh,
        )

    def swept_footprint(self, start: tuple[float, float], end: tuple[float, float]) -> Polygon:
        """The ground the mover's box covers while it goes from ``start`` to ``end``: its footprint stretched along
        the segment (the box keeps its heading on a segment; at a waypoint it turns, inside both stretches)."""
        dx, dy = end[0] - start[0], end[1] - start[1]
        d = math.hypot(dx, dy)
        ux, uy = dx / d, dy / d
        hw, hl = self.width_m / 2, self.length_m / 2
        a = (start[0] - ux * hw, start[1] - uy * hw)
        b = (end[0] + ux * hw, end[1] + uy * hw)
        nx, ny = -uy * hl, ux * hl
        return Polygon([(a[0] - nx, a[1] - ny), (b[0] - nx, b[1] - ny), (b[0] + nx, b[1] + ny), (a[0] + nx, a[1] + ny)])

    def to_dict(self) -> dict[str, Any]:
        """JSON-able and canonical (the moving twin's digest hashes it); ``mesh`` only when set."""
        d = {
            "name": self.name,
            "kind": self.kind,
            "material": self.material,
            "width_m": self.width_m,
            "length_m": self.length_m,
            "height_m": self.height_m,
            "speed_mps": self.speed_mps,
            "waypoints": [list(p) for p in self.waypoints],
            "mode": self.mode,
            "start_offset_s": self.start_offset_s,
        }
        if self.mesh is not None:
            d["mesh"] = self.mesh
        return d


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


# ------------------------------------------------------------------------------------------- the moving twin
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
        if not _finite(self.dt_s) or self.dt_s <= 0:
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
                raise _error(m.name, "two movers have this name", "give every mover a unique name (e.g. 'walker_02')")
            seen.add(m.name)
            if m.name in taken:
                raise _error(
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
                    raise _error(
                        m.name,
                        f"waypoints[{i}] {_xy((x, y))} is outside the grid "
                        f"[{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}] m",
                        "move the waypoint onto the grid: movers walk where the robot can be",
                    )
            if room is not None and m.height_m > room.height_m + _EPS:
                raise _error(
                    m.name,
                    f"height_m = {m.height_m:g} is taller than the room ({room.height_m:g} m)",
                    "lower height_m below the ceiling",
                )
            obstacles = _obstacles(self.base, m.height_m)
            for start, end, i, j in m.segments():
                swept = m.swept_footprint(start, end)
                for label, poly in obstacles:
                    if not swept.intersects(poly) or swept.intersection(poly).area <= _AREA_EPS:
                        continue
                    inside = next((k for k, p in ((i, start), (j, end)) if _inside(p, poly)), None)
                    if inside is not None:
                        problem = f"waypoints[{inside}] {_xy(m.waypoints[inside])} is inside {label}"
                    else:
                        hit = swept.intersection(poly).representative_point()
                        problem = (
                            f"the path from waypoints[{i}] {_xy(start)} to waypoints[{j}] {_xy(end)} runs into "
                            f"{label} near ({hit.x:.2f}, {hit.y:.2f})"
                        )
                    raise _error(
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


# ------------------------------------------------------------------------------------------- the [moving] section
def _positive_seconds(what: str, example: str):
    def check(value: Any) -> float:
        if not _finite(value) or value <= 0:
            raise fail(f"must be a finite number of seconds > 0, got {value!r}", f"write e.g. `{what} = {example}`")
        return float(value)

    return check


def _finite_number(value: Any) -> float:
    if not _finite(value):
        raise fail(f"must be a finite number, got {value!r}", "write a number, e.g. `0.0`")
    return float(value)


def _positive_number(what: str, example: str):
    def check(value: Any) -> float:
        if not _finite(value) or value <= 0:
            raise fail(f"must be a finite number > 0, got {value!r}", f"write e.g. `{what} = {example}`")
        return float(value)

    return check


def _waypoints(value: Any) -> tuple[tuple[float, float], ...]:
    example = "write `waypoints = [[1.0, 2.0], [5.0, 2.0]]` (x, y in scene metres)"
    if not isinstance(value, list):
        raise fail(f"must be an array of [x, y] points, got {value!r}", example)
    if len(value) < 2:
        raise fail(f"has {len(value)} point{'s' * (len(value) != 1)}: a mover needs at least 2", example)
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 2 and all(_finite(v) for v in p)):
            raise fail(f"[{i}] = {p!r} is not a point [x, y] of two finite numbers", example)
    return tuple((float(p[0]), float(p[1])) for p in value)


class MoverModel(SceneFileModel):
    """One ``[[moving.mover]]`` table; sizes, material and mesh default to :data:`MOVER_KINDS` for a known kind."""

    name: ObjName
    kind: ObjName
    speed_mps: Annotated[float, BeforeValidator(_positive_number("speed_mps", "1.0"))]
    waypoints: Annotated[tuple[tuple[float, float], ...], BeforeValidator(_waypoints)]
    mode: Annotated[str, BeforeValidator(choice(MODES, "a mode"))] = "loop"
    start_offset_s: Annotated[float, BeforeValidator(_finite_number)] = 0.0
    material: Material | None = None
    width_m: Annotated[float | None, BeforeValidator(_positive_number("width_m", "0.3"))] = None
    length_m: Annotated[float | None, BeforeValidator(_positive_number("length_m", "0.5"))] = None
    height_m: Annotated[float | None, BeforeValidator(_positive_number("height_m", "1.75"))] = None
    mesh: Annotated[str | None, BeforeValidator(choice(MOVER_MESHES, "a bundled mesh"))] = None


class MovingModel(SceneFileModel):
    """The ``[moving]`` section (a city file's ``quadrant`` is taken out by its reader first)."""

    description: Text
    base: Annotated[str, BeforeValidator(choice(BASE_VARIANTS, "a base variant"))] = "blueprint"
    dt_s: Annotated[float | None, BeforeValidator(_positive_seconds("dt_s", "1.0"))] = None
    horizon_s: Annotated[float | None, BeforeValidator(_positive_seconds("horizon_s", "60.0"))] = None
    mover: list[dict[str, Any]] = []


_MOVER_KEYS = tuple(MoverModel.model_fields)
_MOVING_KEYS = tuple(MovingModel.model_fields)


def _raise_first(exc: ValidationError, origin: str, where: str, allowed: tuple[str, ...]) -> None:
    """The first pydantic complaint about a [moving] table, in the file's words (misspelt keys first)."""
    errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
    e = errors[0]
    loc = [p for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function")))]
    key = next((str(p) for p in loc if isinstance(p, str)), "(table)")
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    if e["type"] == "extra_forbidden":
        close = did_you_mean(key, allowed)
        raise SceneFileError(
            f"{origin}: {where}: unknown key {key!r}" + (f"; {close}" if close else "") + more,
            hint="allowed keys: " + ", ".join(allowed),
        ) from None
    if e["type"] == "missing":
        raise SceneFileError(f"{origin}: {where}: missing field {key!r}" + more, hint=f"add `{key} = ...`") from None
    if e["type"] == "dtradar":
        raise SceneFileError(f"{origin}: {where}: {key} {e['ctx']['problem']}" + more, hint=e["ctx"]["hint"]) from None
    raise SceneFileError(
        f"{origin}: {where}: {key}: {e['msg']}" + more, hint="see the [moving] section of cubicle.toml"
    ) from None


def _mover(raw: Any, i: int, origin: str) -> Mover:
    where = f"moving.mover[{i}]"
    if not isinstance(raw, dict):
        raise SceneFileError(f"{origin}: {where}: must be a table", hint="write it as a [[moving.mover]] block")
    if isinstance(raw.get("name"), str):
        where += f" {raw['name']!r}"
    try:
        m = MoverModel.model_validate(raw)
    except ValidationError as exc:
        _raise_first(exc, origin, where, _MOVER_KEYS)
    given = m.model_dump(include={"width_m", "length_m", "height_m", "material", "mesh"}, exclude_none=True)
    if m.kind in MOVER_KINDS:
        width, length, height, material, mesh = MOVER_KINDS[m.kind]
        values = {"width_m": width, "length_m": length, "height_m": height, "material": material, "mesh": mesh}
        values |= given
    else:
        values = {"mesh": None} | given
        missing = [k for k in ("width_m", "length_m", "height_m", "material") if k not in values]
        if missing:
            close = did_you_mean(m.kind, MOVER_KINDS)
            raise SceneFileError(
                f"{origin}: {where}: kind {m.kind!r} has no default size, and the mover does not give "
                + ", ".join(missing)
                + (f"; {close}" if close else ""),
                hint="give width_m (along its way), length_m (across), height_m and material, or use a kind with "
                "defaults: " + ", ".join(MOVER_KINDS),
            )
    try:
        return Mover(
            name=m.name,
            kind=m.kind,
            speed_mps=m.speed_mps,
            waypoints=m.waypoints,
            mode=m.mode,
            start_offset_s=m.start_offset_s,
            **values,
        )
    except SceneFileError as e:
        raise SceneFileError(f"{origin}: {where}: {e.message.partition(': ')[2]}", hint=e.hint) from None


def moving_scene_from_section(
    section: Any,
    base_spec: Callable[[str], SceneSpec],
    *,
    origin: str,
    title: str,
    description: str,
) -> MovingScene:
    """The moving twin a file's ``[moving]`` section declares: ``base_spec(variant)`` builds the base variant
    (``base = "blueprint"`` by default), ``title`` is the twin's, ``description`` the scene's (the section's own is
    appended). Every problem is a :class:`SceneFileError` naming ``origin`` and the mover."""
    if not isinstance(section, dict):
        raise SceneFileError(f"{origin}: [moving] must be a table", hint="write key = value lines under [moving]")
    try:
        model = MovingModel.model_validate(section)
    except ValidationError as exc:
        _raise_first(exc, origin, "[moving]", _MOVING_KEYS)
    movers = tuple(_mover(raw, i, origin) for i, raw in enumerate(model.mover))
    base = base_spec(model.base)
    dt_s = model.dt_s if model.dt_s is not None else base.grid.cell_m / ROBOT_SPEED_MPS
    if model.horizon_s is not None:
        snapshots = round(model.horizon_s / dt_s)
        if snapshots < 1:
            raise SceneFileError(
                f"{origin}: [moving]: horizon_s = {model.horizon_s:g} is shorter than one step (dt_s = {dt_s:g} s)",
                hint=f"give horizon_s of at least {dt_s:g} s, or drop it for the movers' common period",
            )
        how = "scene file"
    else:
        snapshots = common_snapshots(movers, dt_s) if movers else 1
        exact = movers and math.lcm(*(max(1, round(m.period_s / dt_s)) for m in movers)) <= DEFAULT_MAX_SNAPSHOTS
        how = "common period" if exact else f"capped at {DEFAULT_MAX_SNAPSHOTS} snapshots"
    provenance = {
        "base": model.base,
        "dt_s": dt_s,
        "dt_from": "scene file" if model.dt_s is not None else f"cell_m / {ROBOT_SPEED_MPS} m/s",
        "snapshots": snapshots,
        "horizon_from": how,
    }
    try:
        return MovingScene(
            base=base,
            movers=movers,
            dt_s=dt_s,
            snapshots=snapshots,
            title=title,
            description=f"{description}\n\nMoving twin ({model.base} + {len(movers)} movers): {model.description}",
            provenance=provenance,
        )
    except SceneFileError as e:
        raise SceneFileError(f"{origin}: [moving] {e.message}", hint=e.hint) from None
