"""Geometry of scenes built on a Mitsuba/Sionna XML file (:class:`~dtradar_data.scenes.model.MeshScene`).

trimesh, shapely and scipy only (no Sionna): the XML's shapes as meshes in scene metres (:func:`shape_meshes`), the
ground height under any point (:func:`ground_height`, so receivers ride 1.5 m above San Francisco's terrain), the
building footprints at robot height (:func:`base_footprints`: horizontal sections of every shape standing on the
ground, which occupancy and floor plans use like a city's prisms), and the XML the tracer loads
(:func:`merged_scene_xml`: the external scene with absolute mesh paths, plus the spec's own objects).
"""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from functools import reduce
from pathlib import Path

import numpy as np
import shapely
import trimesh

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.model import MeshScene, SceneSpec
from dtradar_data.scenes.xml_shapes import FILE_SHAPES, PRIMITIVE_SHAPES

FLAT_M = 0.05  # shapes thinner than this (road markings, flat roofs on their own) cannot block the robot
SNAP_M = 1e-4  # section end points are rounded to this so that segments of neighbouring triangles join


# ------------------------------------------------------------------------------------------- meshes
def _to_world(shape: ET.Element) -> np.ndarray:
    """The shape's ``to_world`` transform as a 4x4 matrix (Mitsuba applies the listed operations in order)."""
    m = np.eye(4)
    tr = next((t for t in shape.findall("transform") if t.get("name") == "to_world"), None)
    if tr is None:
        return m
    for op in tr:

        def xyz(default: float, op: ET.Element = op) -> np.ndarray:
            if op.get("value") is not None:
                vals = [float(v) for v in op.get("value").replace(",", " ").split()]
                return np.array(vals * 3 if len(vals) == 1 else vals, dtype=float)
            return np.array([float(op.get(k, default)) for k in "xyz"])

        if op.tag == "matrix":
            step = np.array([float(v) for v in op.get("value").replace(",", " ").split()]).reshape(4, 4)
        elif op.tag == "translate":
            step = trimesh.transformations.translation_matrix(xyz(0.0))
        elif op.tag == "scale":
            step = np.diag([*xyz(1.0), 1.0])
        elif op.tag == "rotate":
            step = trimesh.transformations.rotation_matrix(math.radians(float(op.get("angle", 0))), xyz(0.0))
        else:
            raise SceneFileError(
                f"shape {shape.get('id')!r}: transform <{op.tag}> is not supported",
                hint="use matrix, translate, scale or rotate (or bake the transform into the mesh)",
            )
        m = step @ m
    return m


@functools.lru_cache(maxsize=8)
def _shape_meshes(path: str, sha256: str) -> tuple[tuple[str, trimesh.Trimesh], ...]:
    xml = Path(path)
    out = []
    for i, el in enumerate(ET.parse(xml).getroot().findall("shape")):
        kind, sid = el.get("type", ""), el.get("id") or el.get("name") or f"shape-{i}"
        if kind in FILE_SHAPES:
            fn = next(s.get("value") for s in el.findall("string") if s.get("name") == "filename")
            mesh = trimesh.load(str(xml.parent / fn), process=False, force="mesh")
        elif kind == "rectangle":  # Mitsuba's unit rectangle: [-1, 1]^2 at z = 0
            mesh = trimesh.Trimesh(
                [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]], process=False
            )
        elif kind == "cube":  # Mitsuba's unit cube: [-1, 1]^3
            mesh = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
        else:  # read_shapes rejected it when the spec was made
            raise SceneFileError(
                f"{xml}: shape {sid!r} has type {kind!r}",
                hint=f"use {', '.join(FILE_SHAPES + PRIMITIVE_SHAPES)} shapes",
            )
        mesh.apply_transform(_to_world(el))
        out.append((sid, mesh))
    return tuple(out)


def shape_meshes(base: MeshScene) -> list[tuple[str, trimesh.Trimesh]]:
    """``(shape id, mesh)`` for every shape of the XML, in file order (cached per file content)."""
    return list(_shape_meshes(base.path, base.sha256))


# ------------------------------------------------------------------------------------------- ground
@functools.lru_cache(maxsize=8)
def _ground_interpolator(path: str, sha256: str, ground: tuple[str, ...]):
    parts = [m for sid, m in _shape_meshes(path, sha256) if sid in ground]
    if not parts:
        return 0.0
    v = np.vstack([m.vertices for m in parts])
    if np.ptp(v[:, 2]) < 1e-6:  # a flat ground plane: one height everywhere
        return float(v[0, 2])
    from scipy.interpolate import LinearNDInterpolator

    xy, idx = np.unique(np.round(v[:, :2], 3), axis=0, return_index=True)
    return LinearNDInterpolator(xy, v[idx, 2], fill_value=float(v[:, 2].min()))


def ground_height(spec: SceneSpec, x, y) -> np.ndarray:
    """Height of the ground under each ``(x, y)`` (0 for specs without an XML base; a flat ground's own height;
    a terrain's, interpolated linearly between its vertices, like the surface Sionna traces)."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if spec.base is None:
        return np.zeros(x.shape)
    f = _ground_interpolator(spec.base.path, spec.base.sha256, spec.base.ground)
    return np.full(x.shape, f) if isinstance(f, float) else np.asarray(f(x, y), dtype=float)


# ------------------------------------------------------------------------------------------- footprints
def mesh_section(mesh: trimesh.Trimesh, z: float):
    """The horizontal section of a mesh at height ``z`` as a (multi)polygon, filled even-odd over its closed
    rings (a courtyard stays open); None where the section has no closed ring."""
    seg = trimesh.intersections.mesh_plane(mesh, (0.0, 0.0, 1.0), (0.0, 0.0, z))
    if len(seg) == 0:
        return None
    lines = shapely.line_merge(shapely.multilinestrings(np.round(seg[:, :, :2] / SNAP_M) * SNAP_M))
    rings = [
        shapely.make_valid(shapely.Polygon(p.coords))
        for p in shapely.get_parts(lines)
        if p.is_closed and len(p.coords) >= 4
    ]
    rings = [r for r in rings if r.area > 0]
    return reduce(shapely.symmetric_difference, rings) if rings else None


def mesh_shadow(mesh: trimesh.Trimesh):
    """Union of the mesh's triangles projected on the ground (vertical walls add nothing); None if all are."""
    tri = mesh.triangles[:, :, :2]
    area = 0.5 * np.abs(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    tri = tri[area > 1e-6]
    if len(tri) == 0:
        return None
    return shapely.union_all(shapely.polygons(np.concatenate([tri, tri[:, :1]], axis=1)))


@functools.lru_cache(maxsize=16)
def _footprints(path: str, sha256: str, ground: tuple[str, ...], robot_height_m: float):
    polygons = []
    for sid, mesh in _shape_meshes(path, sha256):
        if sid in ground or len(mesh.faces) == 0:
            continue
        (x0, y0, z0), (x1, y1, z1) = mesh.bounds
        if z1 - z0 < FLAT_M:
            continue
        f = _ground_interpolator(path, sha256, ground)
        g = f if isinstance(f, float) else float(f((x0 + x1) / 2, (y0 + y1) / 2))
        if z0 > g + robot_height_m:  # a roof, canopy or bridge above the robot: it does not stand on the ground
            continue
        # Cut at robot height, or half-way up an object lower than the robot (a low wall still blocks) ...
        footprint = mesh_section(mesh, z0 + min(robot_height_m, (z1 - z0) / 2))
        if footprint is not None and not footprint.is_empty:
            polygons.append(footprint)
        # ... and add the shape's shadow from above: exported city meshes are rarely closed (Munich's Neues
        # Rathaus: open walls, its roof a separate shape), so their sections miss buildings their roofs do show.
        shadow = mesh_shadow(mesh)
        if shadow is not None:
            polygons.append(shadow)
    if not polygons:
        return ()
    merged = shapely.union_all(polygons)
    return tuple(p for p in shapely.get_parts(merged) if isinstance(p, shapely.Polygon) and p.area > 0)


def base_footprints(spec: SceneSpec) -> list[shapely.Polygon]:
    """Footprints at robot height of everything in the XML that stands on the ground (not the ground itself, not
    what hangs above the robot): its section at robot height and its shadow from above, merged: ``[]`` without an XML
    base. Cached per file content and robot height."""
    if spec.base is None:
        return []
    b = spec.base
    return list(_footprints(b.path, b.sha256, b.ground, float(spec.robot_height_m)))


# ------------------------------------------------------------------------------------------- the tracer's XML
def merged_scene_xml(base: MeshScene, own_xml: str) -> str:
    """The external scene with its mesh paths made absolute (so the merged file can live anywhere), plus the
    materials and shapes of ``own_xml`` (the spec's own objects, as :func:`~.meshes.write_mitsuba_scene` writes
    them). A material id the external scene already defines is taken from it; a clashing shape id is prefixed."""
    xml = Path(base.path)
    root = ET.parse(xml).getroot()
    for el in root.iter("shape"):
        for s in el.findall("string"):
            if s.get("name") == "filename":
                s.set("value", str((xml.parent / s.get("value")).resolve()))
    ids = {el.get("id") for el in root.iter() if el.get("id") and el.tag != "ref"}
    own = ET.fromstring(own_xml)
    for el in own.findall("bsdf"):
        if el.get("id") not in ids:
            root.append(el)
    for el in own.findall("shape"):
        if el.get("id") in ids:
            el.set("id", "dtradar-" + el.get("id"))
        root.append(el)
    root.insert(0, ET.Comment(f" dtradar: {base.xml} (sha256 {base.sha256}) with the spec's own objects "))
    return ET.tostring(root, encoding="unicode") + "\n"
