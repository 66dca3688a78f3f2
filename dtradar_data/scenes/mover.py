"""One mover: a person walking or a vehicle driving through a frozen scene, at constant speed along its waypoints.

A twin is frozen (:class:`~dtradar_data.scenes.model.SceneSpec`); a real room or street is not. A :class:`Mover` is
one thing that moves: a person walking along waypoints indoors (about 1 m/s), a car or a bus driving along a lane
in a city (a few m/s), at constant speed along the polyline of its waypoints, round a ``"loop"`` (back to the first
waypoint) or ``"back-and-forth"``. At any time it is a :class:`Box` of the existing model (:meth:`Mover.box_at`)
whose local x points where it goes, so Sionna's car mesh, which faces local x, drives forwards. The moving twin that
samples movers over a base scene is :mod:`dtradar_data.scenes.moving_scene`; the ``[moving]`` section of a scene
file that declares them is read by :mod:`dtradar_data.scenes.moving_section`.

Every mistake is a :class:`~dtradar_data.core.errors.SceneFileError` that names the mover and says what to change:
too few waypoints, non-finite or non-positive sizes and speeds, an unknown material, mode or mesh, a repeated
waypoint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from shapely.geometry import Polygon

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.materials import ITU_MATERIALS
from dtradar_data.scenes.model import Box

__all__ = ["MODES", "MOVER_MESHES", "Mover"]

MODES = ("loop", "back-and-forth")
#: Meshes a mover may be drawn with: the keys of :data:`dtradar_data.geometry.meshes.BUNDLED_MESHES` (a test keeps
#: the two equal; scenes sit below geometry and cannot import it).
MOVER_MESHES = ("sionna:low_poly_car",)
_CORNER_EPS = 1e-9  # metres: a mover this close to a waypoint is on the next segment (its heading turns there)


def mover_error(mover: str, problem: str, hint: str) -> SceneFileError:
    """A :class:`SceneFileError` about the mover named ``mover``."""
    return SceneFileError(f"mover {mover!r}: {problem}", hint=hint)


def is_finite(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def point_text(p: tuple[float, float]) -> str:
    """``(x, y)`` as a message shows it."""
    return f"({p[0]:g}, {p[1]:g})"


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
        self._check_fields()
        self._check_waypoints()

    def _check_fields(self) -> None:
        """Names, material, sizes, speed, start offset, mode and mesh."""
        name = self.name
        for key in ("kind", "material"):
            if not isinstance(getattr(self, key), str) or not getattr(self, key):
                raise mover_error(
                    name, f"{key} {getattr(self, key)!r} is not a name", f"give {key}, e.g. kind = 'person'"
                )
        if self.material not in ITU_MATERIALS:
            close = did_you_mean(self.material, ITU_MATERIALS)
            raise mover_error(
                name,
                f"material {self.material!r} is not an ITU material" + (f"; {close}" if close else ""),
                "use one of: " + ", ".join(ITU_MATERIALS),
            )
        for key in ("width_m", "length_m", "height_m", "speed_mps"):
            value = getattr(self, key)
            if not is_finite(value) or value <= 0:
                unit = "m/s, e.g. speed_mps = 1.0 for a walk" if key == "speed_mps" else "metres"
                raise mover_error(name, f"{key} = {value!r} must be a finite number > 0", f"give {key} in {unit}")
        if not is_finite(self.start_offset_s):
            raise mover_error(
                name,
                f"start_offset_s = {self.start_offset_s!r} must be a finite number",
                "give the seconds into its route the mover is at t = 0, e.g. 0",
            )
        if self.mode not in MODES:
            close = did_you_mean(str(self.mode), MODES)
            raise mover_error(
                name,
                f"mode {self.mode!r} is not a mode" + (f"; {close}" if close else ""),
                "use 'loop' or 'back-and-forth'",
            )
        if self.mesh is not None and self.mesh not in MOVER_MESHES:
            close = did_you_mean(str(self.mesh), MOVER_MESHES)
            raise mover_error(
                name,
                f"mesh {self.mesh!r} is not a bundled mesh" + (f"; {close}" if close else ""),
                "use one of: " + ", ".join(MOVER_MESHES) + ", or drop mesh to draw the box itself",
            )

    def _check_waypoints(self) -> None:
        """At least two points ``[x, y]``, stored as float pairs; no point repeated next to itself, and no loop that
        repeats its first point at the end."""
        name = self.name
        points = self.waypoints
        if not isinstance(points, (list, tuple)) or len(points) < 2:
            count = len(points) if isinstance(points, (list, tuple)) else points
            raise mover_error(
                name,
                f"needs at least 2 waypoints, has {count!r}",
                "give waypoints = [[x0, y0], [x1, y1], ...] in scene metres (2 or more)",
            )
        clean = []
        for i, p in enumerate(points):
            if not (isinstance(p, (list, tuple)) and len(p) == 2 and all(is_finite(v) for v in p)):
                raise mover_error(
                    name, f"waypoints[{i}] = {p!r} is not a point", "write each waypoint as [x, y] in metres"
                )
            clean.append((float(p[0]) + 0.0, float(p[1]) + 0.0))
        object.__setattr__(self, "waypoints", tuple(clean))
        for i in range(len(clean) - 1):
            if clean[i] == clean[i + 1]:
                raise mover_error(
                    name,
                    f"waypoints[{i}] and waypoints[{i + 1}] are the same point {point_text(clean[i])}",
                    "drop the repeated waypoint: a mover has no heading on a path of length 0",
                )
        if self.mode == "loop" and len(clean) > 2 and clean[0] == clean[-1]:
            raise mover_error(
                name,
                f"the last waypoint repeats the first {point_text(clean[0])}",
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
        if not is_finite(t_s):
            raise mover_error(
                self.name, f"time {t_s!r} is not a finite number of seconds", "give t_s in seconds, e.g. 0.0"
            )
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
