"""Where the robot can be: the occupancy grid of a scene, obstacle footprints, connected free regions.

numpy and shapely (no Sionna): a cell is blocked when an obstacle or a building overlaps it at robot height
(:func:`occupancy`);
:func:`free_components` labels the 4-connected free regions the robot can move in.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon

from dtradar_data.geometry.xml_meshes import base_footprints
from dtradar_data.scenes.model import Box, SceneSpec

OCCUPANCY_FLOOR_CLEARANCE_M = 0.05  # ignore objects wholly below this (rugs, cables): the robot drives over them
#: A city cell is blocked when buildings cover at least this share of it. City cells are metres wide (the robot is
#: not): the indoor rule (any overlap blocks) would close most streets at 4 m cells; half keeps a building's cells
#: blocked and the street in front of it open. Vehicles and other boxes keep the indoor rule.
BUILDING_BLOCK_FRACTION = 0.5


def footprints(spec: SceneSpec, include_structure: bool = False) -> list[tuple[Box, np.ndarray]]:
    """``(box, corners float64[4, 2])`` for every obstacle (walls included), lowest first so that things standing on
    others (laptops on tables) draw on top. ``include_structure=True`` adds the floor and ceiling slabs."""
    boxes = spec.objects if include_structure else spec.obstacles()
    order = sorted(range(len(boxes)), key=lambda i: (boxes[i].z_m, boxes[i].top_m, i))
    return [(boxes[i], boxes[i].corners()) for i in order]


def _overlap_cells(corners: np.ndarray, cx: np.ndarray, cy: np.ndarray, half: float, eps: float) -> np.ndarray:
    """Separating-axis test of one convex quadrilateral against axis-aligned squares centred at (cx, cy).

    Axes: x, y and the quadrilateral's two edge normals. The squares overlap the polygon when the projections overlap
    by more than ``eps`` on every axis, so a box that merely touches a cell edge does not block that cell.
    """
    hit = np.ones(cx.shape, dtype=bool)
    for axis in (np.array([1.0, 0.0]), np.array([0.0, 1.0])):
        p = corners @ axis
        c = cx * axis[0] + cy * axis[1]
        hit &= (np.minimum(p.max(), c + half) - np.maximum(p.min(), c - half)) > eps
    for edge in (corners[1] - corners[0], corners[2] - corners[1]):
        n = np.array([-edge[1], edge[0]]) / np.hypot(*edge)
        p = corners @ n
        c = cx * n[0] + cy * n[1]
        r = half * (abs(n[0]) + abs(n[1]))  # projected half-extent of a square of half side `half`
        hit &= (np.minimum(p.max(), c + r) - np.maximum(p.min(), c - r)) > eps
    return hit


def occupancy(spec: SceneSpec, *, eps: float = 1e-6) -> np.ndarray:
    """bool[ny, nx]: True where the robot cannot be.

    Rule: a cell is blocked when an obstacle (any box except floor and ceiling slabs; walls count) whose vertical
    span ``[z_m, z_m + height_m]`` overlaps ``[0.05 m, robot_height_m]`` covers any part of the cell with positive
    area. The overlap is exact (separating-axis test of the rotated footprint against the square cell), with ``eps``
    (1 micrometre) of slack so that a box flush with a cell edge leaves the neighbour free. Consequences: a wall-
    mounted TV above the robot does not block; a table (0.75 m) does; a cell is blocked if a chair clips its corner.
    Prisms (buildings) block a cell when together they cover at least half of it (:data:`BUILDING_BLOCK_FRACTION`,
    exact polygon intersection with shapely); parking-lot and road surfaces lie below 0.05 m and never block. A
    scene built on an XML file adds its footprints at robot height (:func:`.xml_meshes.base_footprints`) under the
    same half-cover rule; its ground never blocks.
    """
    g = spec.grid
    blocked = np.zeros(g.shape, dtype=bool)
    xs, ys = g.centres()
    half = g.cell_m / 2
    lo, hi = OCCUPANCY_FLOOR_CLEARANCE_M, spec.robot_height_m
    for box, corners in footprints(spec):
        if not (box.z_m < hi and box.top_m > lo):
            continue
        # Candidate cells from the footprint's bounding box, then the exact test on them only.
        ix0 = max(0, math.floor((corners[:, 0].min() - g.x0_m) / g.cell_m + 0.5))
        ix1 = min(g.nx - 1, math.floor((corners[:, 0].max() - g.x0_m) / g.cell_m + 0.5))
        iy0 = max(0, math.floor((corners[:, 1].min() - g.y0_m) / g.cell_m + 0.5))
        iy1 = min(g.ny - 1, math.floor((corners[:, 1].max() - g.y0_m) / g.cell_m + 0.5))
        if ix0 > ix1 or iy0 > iy1:
            continue
        cx, cy = np.meshgrid(xs[ix0 : ix1 + 1], ys[iy0 : iy1 + 1])
        blocked[iy0 : iy1 + 1, ix0 : ix1 + 1] |= _overlap_cells(corners, cx, cy, half, eps)
    covered = np.zeros(g.shape)
    for prism in spec.prisms:
        if prism.z_m < hi and prism.top_m > lo:
            _add_cover(covered, g, Polygon(prism.exterior, prism.holes))
    for polygon in base_footprints(spec):  # an XML scene's buildings, sectioned at robot height
        _add_cover(covered, g, polygon)
    blocked |= covered >= BUILDING_BLOCK_FRACTION * g.cell_m * g.cell_m - eps
    return blocked


def _add_cover(covered: np.ndarray, g, polygon: Polygon) -> None:
    """Add to ``covered`` the area of each cell that a (possibly concave, holed) polygon covers."""
    xmin, ymin, xmax, ymax = polygon.bounds
    ix0 = max(0, math.floor((xmin - g.x0_m) / g.cell_m + 0.5))
    ix1 = min(g.nx - 1, math.floor((xmax - g.x0_m) / g.cell_m + 0.5))
    iy0 = max(0, math.floor((ymin - g.y0_m) / g.cell_m + 0.5))
    iy1 = min(g.ny - 1, math.floor((ymax - g.y0_m) / g.cell_m + 0.5))
    if ix0 > ix1 or iy0 > iy1:
        return
    xs, ys = g.centres()
    cx, cy = np.meshgrid(xs[ix0 : ix1 + 1], ys[iy0 : iy1 + 1])
    h = g.cell_m / 2
    cells = shapely.box(cx - h, cy - h, cx + h, cy + h)
    shapely.prepare(polygon)
    covered[iy0 : iy1 + 1, ix0 : ix1 + 1] += shapely.area(shapely.intersection(cells, polygon))


def free_components(blocked: np.ndarray) -> np.ndarray:
    """int32[ny, nx] labels of the 4-connected free regions (the robot moves X-/X+/Y-/Y+): 0 on blocked cells,
    1 for the largest region, 2 for the next largest, ... (ties by first cell in row-major order)."""
    free = ~np.asarray(blocked, dtype=bool)
    ny, nx = free.shape
    labels = np.zeros(free.shape, dtype=np.int32)
    sizes: list[int] = []
    for start in zip(*np.nonzero(free)):
        if labels[start]:
            continue
        label = len(sizes) + 1
        labels[start] = label
        stack, size = [start], 0
        while stack:
            y, x = stack.pop()
            size += 1
            for yy, xx in ((y - 1, x), (y + 1, x), (y, x - 1), (y, x + 1)):
                if 0 <= yy < ny and 0 <= xx < nx and free[yy, xx] and not labels[yy, xx]:
                    labels[yy, xx] = label
                    stack.append((yy, xx))
        sizes.append(size)
    # Relabel by decreasing size (stable), so label 1 is always the largest region.
    order = sorted(range(len(sizes)), key=lambda k: -sizes[k])
    remap = np.zeros(len(sizes) + 1, dtype=np.int32)
    remap[[k + 1 for k in order]] = np.arange(1, len(sizes) + 1, dtype=np.int32)
    return remap[labels]


def largest_free_component(blocked: np.ndarray) -> np.ndarray:
    """bool[ny, nx]: the free cells of the largest 4-connected region; draw start/target pairs from it so that
    every pair is reachable."""
    return free_components(blocked) == 1


def largest_free_component_fraction(blocked: np.ndarray) -> float:
    """Share of the free cells that lie in the largest 4-connected free region (1.0 when all free cells connect)."""
    total = int((~np.asarray(blocked, dtype=bool)).sum())
    return float(largest_free_component(blocked).sum()) / total if total else 0.0
