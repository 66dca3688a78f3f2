"""Geometry of a :class:`~dtradar_data.scene.SceneSpec`: triangle meshes, the Sionna/Mitsuba scene files and the
occupancy grid. trimesh + numpy only: this module never imports Sionna or Mitsuba, so it tests without them.

- :func:`material_meshes` builds each box as a closed 12-triangle mesh with outward normals and concatenates the
  boxes of one ITU material into one mesh (vertices are *not* welded across boxes, so every box stays a closed
  2-manifold even where two boxes touch).
- :func:`write_mitsuba_scene` writes ``meshes/<material>.ply`` (binary little endian, written by hand so the bytes
  depend only on the spec) and ``scene.xml`` in the Sionna RT 2.x format.
- :func:`occupancy` is the robot's blocked-cell map, :func:`footprints` the polygons for drawing.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh

from .scene import Box, SceneSpec

# Slab thickness per material for Sionna's transmission model (it treats every surface a ray crosses as a slab of the
# material's thickness; Sionna's default is 0.1 m). Our obstacles are closed boxes, so a ray through one crosses two
# faces: thicknesses are roughly half the real solid, or the panel thickness for hollow furniture.
MATERIAL_THICKNESS_M: dict[str, float] = {
    "brick": 0.1,          # 0.2 m walls
    "concrete": 0.1,       # floor and ceiling slabs (only their inner faces are ever hit)
    "wood": 0.02,          # chair seats/backs, table tops, board, rack panels: ~2 cm boards
    "chipboard": 0.01,     # cardboard boxes
    "metal": 0.002,        # sheet metal; metal does not transmit at 2.4 GHz anyway
    "wet_ground": 0.15,    # stands in for a human body (~0.3 m deep)
    "glass": 0.01,
    "plasterboard": 0.0125,
}
DEFAULT_THICKNESS_M = 0.1
OCCUPANCY_FLOOR_CLEARANCE_M = 0.05  # ignore objects wholly below this (rugs, cables): the robot drives over them


def material_thickness(material: str) -> float:
    return MATERIAL_THICKNESS_M.get(material, DEFAULT_THICKNESS_M)


# ---------------------------------------------------------------------------------------------------- meshes
def box_mesh(box: Box) -> trimesh.Trimesh:
    """A closed box mesh (8 vertices, 12 triangles, outward normals) placed and rotated as ``box`` says."""
    mesh = trimesh.creation.box(extents=(box.width_m, box.length_m, box.height_m))
    transform = trimesh.transformations.rotation_matrix(math.radians(box.yaw_deg), (0.0, 0.0, 1.0))
    transform[:3, 3] = (box.x_m, box.y_m, box.z_m + box.height_m / 2)
    mesh.apply_transform(transform)
    return mesh


def material_meshes(spec: SceneSpec) -> dict[str, trimesh.Trimesh]:
    """One mesh per ITU material (keys sorted), boxes in the spec's object order."""
    groups: dict[str, list[Box]] = {}
    for box in spec.objects:
        groups.setdefault(box.material, []).append(box)
    out = {}
    for material in sorted(groups):
        parts = [box_mesh(b) for b in groups[material]]
        vertices, faces, offset = [], [], 0
        for p in parts:
            vertices.append(p.vertices)
            faces.append(p.faces + offset)
            offset += len(p.vertices)
        # process=False: keep each box's own vertices; welding across touching boxes would create edges shared by
        # four faces and break watertightness.
        out[material] = trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=False)
    return out


def _ply_bytes(mesh: trimesh.Trimesh) -> bytes:
    """Binary little-endian PLY with float32 x, y, z and uchar-counted int32 triangle indices."""
    vertices = np.ascontiguousarray(mesh.vertices, dtype="<f4")
    faces = np.asarray(mesh.faces, dtype="<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment dtradar scene mesh\n"
        f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    face_records = np.zeros(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    face_records["n"] = 3
    face_records["idx"] = faces
    return header + vertices.tobytes() + face_records.tobytes()


def _write_if_changed(path: Path, data: bytes) -> None:
    if not (path.exists() and path.read_bytes() == data):
        path.write_bytes(data)


def write_mitsuba_scene(spec: SceneSpec, out_dir: Path) -> Path:
    """Write ``out_dir/scene.xml`` and ``out_dir/meshes/<material>.ply``; return the XML path.

    The XML follows Sionna RT 2.x's bundled scenes: one ``itu-radio-material`` BSDF per material with id
    ``itu_<material>`` (the prefix Sionna's loader recognises), a ``type`` string and a ``thickness`` float, and one
    ``ply`` shape per material with ``face_normals`` (flat boxes need no smoothed normals). Shape ids are
    ``mesh-<material>``, so Sionna names the objects after their material. Same spec, same bytes.
    """
    out_dir = Path(out_dir)
    (out_dir / "meshes").mkdir(parents=True, exist_ok=True)
    meshes = material_meshes(spec)
    lines = ['<scene version="2.1.0">', "", f"<!-- dtradar scene {spec.name} (spec sha256 {spec.digest()}) -->",
             "", "<!-- Materials -->", ""]
    for material in meshes:
        lines += [f'\t<bsdf type="itu-radio-material" id={quoteattr("itu_" + material)}>',
                  f'\t\t<string name="type" value={quoteattr(material)}/>',
                  f'\t\t<float name="thickness" value="{material_thickness(material)!r}"/>',
                  "\t</bsdf>"]
    lines += ["", "<!-- Shapes -->", ""]
    for material, mesh in meshes.items():
        _write_if_changed(out_dir / "meshes" / f"{material}.ply", _ply_bytes(mesh))
        lines += [f'\t<shape type="ply" id={quoteattr("mesh-" + material)}>',
                  f'\t\t<string name="filename" value={quoteattr(f"meshes/{material}.ply")}/>',
                  '\t\t<boolean name="face_normals" value="true"/>',
                  f'\t\t<ref id={quoteattr("itu_" + material)} name="bsdf"/>',
                  "\t</shape>"]
    lines += ["</scene>", ""]
    xml_path = out_dir / "scene.xml"
    _write_if_changed(xml_path, "\n".join(lines).encode("utf-8"))
    return xml_path


# ---------------------------------------------------------------------------------------------------- 2-D views
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
        cx, cy = np.meshgrid(xs[ix0:ix1 + 1], ys[iy0:iy1 + 1])
        blocked[iy0:iy1 + 1, ix0:ix1 + 1] |= _overlap_cells(corners, cx, cy, half, eps)
    return blocked


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
