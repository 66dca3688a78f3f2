"""Streets of a city quadrant: the transmitter's place in them, road centrelines, and vehicles parked on them.

Everything here is deterministic: the same buildings, roads and seed give the same placements, bit for bit.

- :func:`place_transmitter`: the paper's transmitter coordinates fall inside buildings in our frame; move each to
  the nearest point of the quadrant's largest open region (its streets, not a courtyard) at least ``clearance_m``
  from every building, keeping its height.
- :func:`find_roads`: the widest straight corridors free of buildings, along the street grid's direction (the
  length-weighted dominant direction of the building edges). Used when a city's roads are not known in advance.
- :func:`place_vehicles`: cars and buses on the roads' two lanes, at seeded positions, never overlapping each other
  or a building. Cars are drawn with Sionna's bundled low-poly car mesh, buses are metal boxes of a bus's size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry import box as shapely_box
from shapely.ops import nearest_points, unary_union

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.model import Box

#: kind -> (length, width, height in metres, material, bundled mesh). Car: Sionna's low-poly car as it comes
#: (4.4 x 1.8 x 1.5 m); bus: a 12 m city bus (2.55 m wide, 3.2 m high), metal like the car bodies.
VEHICLES: dict[str, tuple[float, float, float, str, str | None]] = {
    "car": (4.4, 1.8, 1.5, "metal", "sionna:low_poly_car"),
    "bus": (12.0, 2.55, 3.2, "metal", None),
}
LANE_OFFSET_M = 1.75  # half a 3.5 m lane: vehicles drive on either side of the centreline
VEHICLE_GAP_M = 2.0  # at least this much space between two vehicles
ROAD_END_MARGIN_M = 5.0  # no vehicle within this distance of a road's ends (the quadrant's edge)
MAX_TRIES = 500


@dataclass(frozen=True)
class Road:
    """A straight road centreline in scene metres."""

    name: str
    start: tuple[float, float]
    end: tuple[float, float]

    @property
    def line(self) -> LineString:
        return LineString([self.start, self.end])

    @property
    def heading_deg(self) -> float:
        return math.degrees(math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0]))

    def to_dict(self) -> dict:
        return {"name": self.name, "from_m": list(self.start), "to_m": list(self.end)}


def place_transmitter(
    paper_xy: tuple[float, float], buildings: list[Polygon], area: Polygon, clearance_m: float
) -> tuple[float, float]:
    """The point of ``area`` nearest ``paper_xy`` that is at least ``clearance_m`` from every building."""
    # a buffer is a polygon inside the true offset curve: pad it by a centimetre so the clearance holds exactly
    free = area.difference(unary_union(buildings).buffer(clearance_m + 0.01, quad_segs=16)) if buildings else area
    # the street network, not a courtyard: the largest open region of the quadrant
    free = max(getattr(free, "geoms", [free]), key=lambda g: g.area)
    if free.is_empty:
        raise SceneFileError(
            f"no point of the quadrant is {clearance_m} m from every building",
            hint="lower [tx] clearance_m in the city scene file",
        )
    p = Point(paper_xy)
    if free.covers(p):
        return float(paper_xy[0]), float(paper_xy[1])
    q = nearest_points(free, p)[0]
    return round(float(q.x), 3), round(float(q.y), 3)


def street_direction_deg(buildings: list[Polygon]) -> float:
    """The street grid's direction in [0, 90): the length-weighted most common building edge direction mod 90."""
    weights = np.zeros(180)
    for poly in buildings:
        xy = np.asarray(poly.exterior.coords)
        d = np.diff(xy, axis=0)
        ang = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 90.0
        np.add.at(weights, np.minimum((ang * 2).astype(int), 179), np.hypot(d[:, 0], d[:, 1]))
    return float(np.argmax(weights)) / 2 + 0.25 if weights.any() else 0.0


def find_roads(
    buildings: list[Polygon],
    area: Polygon,
    *,
    n: int = 2,
    clearance_m: float = 7.0,
    min_length_m: float = 60.0,
    step_m: float = 1.0,
) -> list[Road]:
    """The ``n`` longest straight corridors through ``area`` at least ``clearance_m`` from every building, along
    either street direction; each is returned as the centreline of its run of free parallel lines."""
    blocked = unary_union(buildings).buffer(clearance_m) if buildings else Polygon()
    xmin, ymin, xmax, ymax = area.bounds
    reach = math.hypot(xmax - xmin, ymax - ymin)
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    base = street_direction_deg(buildings)
    corridors = []
    for angle in (base, base + 90.0):
        t = math.radians(angle)
        d, normal = np.array([math.cos(t), math.sin(t)]), np.array([-math.sin(t), math.cos(t)])
        run: list[LineString] = []
        for off in np.arange(-reach / 2, reach / 2 + step_m, step_m):
            c = centre + normal * off
            line = LineString([c - d * reach, c + d * reach]).intersection(area)
            free = line.difference(blocked) if not line.is_empty else line
            parts = [g for g in getattr(free, "geoms", [free]) if not g.is_empty and g.length >= min_length_m]
            best = max(parts, key=lambda g: g.length, default=None)
            if best is not None and (not run or best.distance(run[-1]) <= step_m * 1.5):
                run.append(best)
                continue
            if run:
                corridors.append(run)
            run = [best] if best is not None else []
        if run:
            corridors.append(run)
    # widest first, then longest: the middle line of a wide corridor is a street, a thin one a gap between houses
    corridors.sort(key=lambda r: (-len(r), -r[len(r) // 2].length))
    roads = []
    for i, run in enumerate(corridors[:n]):
        mid = run[len(run) // 2]
        (x0, y0), (x1, y1) = mid.coords[0], mid.coords[-1]
        roads.append(Road(f"street_{chr(ord('a') + i)}", (round(x0, 2), round(y0, 2)), (round(x1, 2), round(y1, 2))))
    if len(roads) < n:
        raise SceneFileError(
            f"found {len(roads)} of {n} free straight roads in the quadrant",
            hint="list the roads in the city scene file: roads = [{name, from_m, to_m}, ...]",
        )
    return roads


def vehicle_footprint(x: float, y: float, length: float, width: float, heading_deg: float) -> Polygon:
    t = math.radians(heading_deg)
    c, s = math.cos(t), math.sin(t)
    corners = [(-length / 2, -width / 2), (length / 2, -width / 2), (length / 2, width / 2), (-length / 2, width / 2)]
    return Polygon([(x + c * u - s * v, y + s * u + c * v) for u, v in corners])


def place_vehicles(
    roads: list[Road], counts: dict[str, int], seed: int, buildings: list[Polygon], area: Polygon
) -> list[Box]:
    """``counts`` vehicles per kind (buses first, they need the most room) on random lanes and positions of
    ``roads``; each is a :class:`Box` named ``<kind>_NN`` with its heading along the lane's direction of travel."""
    rng = np.random.default_rng(seed)
    obstacles = unary_union(buildings) if buildings else Polygon()
    placed: list[Polygon] = []
    boxes: list[Box] = []
    for kind in sorted(counts, key=lambda k: -VEHICLES[k][0]):
        length, width, height, material, mesh = VEHICLES[kind]
        for k in range(counts[kind]):
            for _ in range(MAX_TRIES):
                road = roads[int(rng.integers(len(roads)))]
                lane = 1 if rng.random() < 0.5 else -1  # right-hand traffic: lane +1 drives from start to end
                line = road.line
                lo, hi = ROAD_END_MARGIN_M + length / 2, line.length - ROAD_END_MARGIN_M - length / 2
                if hi <= lo:
                    continue
                s = float(rng.uniform(lo, hi))
                p = line.interpolate(s)
                heading = road.heading_deg if lane == 1 else road.heading_deg + 180.0
                t = math.radians(road.heading_deg)
                x, y = p.x + math.sin(t) * LANE_OFFSET_M * lane, p.y - math.cos(t) * LANE_OFFSET_M * lane
                fp = vehicle_footprint(x, y, length, width, heading)
                if not area.contains(fp) or fp.intersects(obstacles):
                    continue
                if any(fp.distance(other) < VEHICLE_GAP_M for other in placed):
                    continue
                placed.append(fp)
                boxes.append(
                    Box(
                        name=f"{kind}_{k + 1:02d}",
                        kind=kind,
                        material=material,
                        x_m=round(x, 3),
                        y_m=round(y, 3),
                        width_m=length,
                        length_m=width,
                        height_m=height,
                        yaw_deg=round(heading % 360.0, 3),
                        mesh=mesh,
                    )
                )
                break
            else:
                raise SceneFileError(
                    f"could not place {kind} {k + 1} of {counts[kind]} on the roads "
                    f"({', '.join(r.name for r in roads)}) after {MAX_TRIES} tries",
                    hint="lengthen the roads or lower the vehicle counts in [dynamic]",
                )
    return boxes


def quadrant_rect(quadrant: str, hx: float, hy: float) -> Polygon:
    """Q1 = [-hx, 0] x [-hy, 0] (south-west), Q2 north-west, Q3 north-east, Q4 south-east."""
    sx, sy = QUADRANT_SIGNS[quadrant]
    xs, ys = sorted((0.0, sx * hx)), sorted((0.0, sy * hy))
    return shapely_box(xs[0], ys[0], xs[1], ys[1])


QUADRANT_SIGNS: dict[str, tuple[int, int]] = {"q1": (-1, -1), "q2": (-1, 1), "q3": (1, 1), "q4": (1, -1)}

__all__ = [
    "Road",
    "VEHICLES",
    "find_roads",
    "place_transmitter",
    "place_vehicles",
    "quadrant_rect",
    "street_direction_deg",
    "vehicle_footprint",
    "QUADRANT_SIGNS",
]
