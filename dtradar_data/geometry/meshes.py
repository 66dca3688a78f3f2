"""Triangle meshes of a :class:`~dtradar_data.scenes.model.SceneSpec` and the Sionna/Mitsuba scene files.

trimesh + numpy only: this module never imports Sionna or Mitsuba, so it tests without them.

- :func:`material_meshes` builds each box as a closed 12-triangle mesh with outward normals (or a bundled mesh, such
  as Sionna's low-poly car, scaled into the box), each prism as its extruded footprint (``trimesh`` with
  ``mapbox-earcut`` triangulating the caps), and concatenates the parts of one ITU material into one mesh (vertices
  are *not* welded across parts, so every part stays a closed 2-manifold even where two touch).
- :func:`write_mitsuba_scene` writes ``meshes/<material>.ply`` (binary little endian, written by hand so the bytes
  depend only on the spec) and ``scene.xml`` in the Sionna RT 2.x format (for a spec built on an external XML, that
  scene with the spec's objects added: :mod:`.xml_meshes`).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh
from shapely.geometry import Polygon

from dtradar_data.core.errors import unknown_name
from dtradar_data.core.files import installed_file
from dtradar_data.geometry.xml_meshes import merged_scene_xml
from dtradar_data.scenes.model import Box, Prism, SceneSpec

# Slab thickness per material for Sionna's transmission model (it treats every surface a ray crosses as a slab of the
# material's thickness; Sionna's default is 0.1 m). Our obstacles are closed boxes, so a ray through one crosses two
# faces: thicknesses are roughly half the real solid, or the panel thickness for hollow furniture.
MATERIAL_THICKNESS_M: dict[str, float] = {
    "brick": 0.1,  # 0.2 m walls
    "concrete": 0.1,  # floor and ceiling slabs (only their inner faces are ever hit)
    "wood": 0.02,  # chair seats/backs, table tops, board, rack panels: ~2 cm boards
    "chipboard": 0.01,  # cardboard boxes
    "metal": 0.002,  # sheet metal; metal does not transmit at 2.4 GHz anyway
    "wet_ground": 0.15,  # stands in for a human body (~0.3 m deep)
    "glass": 0.01,
    "plasterboard": 0.0125,
}
DEFAULT_THICKNESS_M = 0.1


def material_thickness(material: str) -> float:
    return MATERIAL_THICKNESS_M.get(material, DEFAULT_THICKNESS_M)


#: Meshes a box may be drawn with (``Box.mesh``): the file inside an installed distribution. Found through package
#: metadata, not by importing the package, so this layer never imports Sionna.
BUNDLED_MESHES: dict[str, tuple[str, str]] = {
    "sionna:low_poly_car": ("sionna-rt", "sionna/rt/scenes/low_poly_car.ply"),
}


# ---------------------------------------------------------------------------------------------------- meshes
@functools.cache
def bundled_mesh(name: str) -> trimesh.Trimesh:
    """A bundled mesh by name, centred on its footprint with its bottom at z = 0."""
    if name not in BUNDLED_MESHES:
        raise unknown_name("bundled mesh", name, BUNDLED_MESHES)
    dist, rel = BUNDLED_MESHES[name]
    path = installed_file(dist, rel, f"the mesh {name!r}")
    mesh = trimesh.load(str(path), process=False, force="mesh")
    lo, hi = mesh.bounds
    mesh.apply_translation((-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]))
    return mesh


def box_mesh(box: Box) -> trimesh.Trimesh:
    """A closed box mesh (8 vertices, 12 triangles, outward normals) placed and rotated as ``box`` says; with
    ``box.mesh`` the bundled mesh scaled to the box's size instead."""
    if box.mesh is None:
        mesh = trimesh.creation.box(extents=(box.width_m, box.length_m, box.height_m))
        lift = box.z_m + box.height_m / 2
    else:
        mesh = bundled_mesh(box.mesh).copy()
        mesh.apply_scale(np.array([box.width_m, box.length_m, box.height_m]) / mesh.extents)
        lift = box.z_m
    transform = trimesh.transformations.rotation_matrix(math.radians(box.yaw_deg), (0.0, 0.0, 1.0))
    transform[:3, 3] = (box.x_m, box.y_m, lift)
    mesh.apply_transform(transform)
    return mesh


def prism_mesh(prism: Prism) -> trimesh.Trimesh:
    """The footprint extruded from ``z_m`` to its top: a closed mesh with outward normals."""
    polygon = Polygon(prism.exterior, prism.holes)
    mesh = trimesh.creation.extrude_polygon(polygon, prism.height_m, engine="earcut")
    mesh.apply_translation((0.0, 0.0, prism.z_m))
    return mesh


def material_meshes(spec: SceneSpec) -> dict[str, trimesh.Trimesh]:
    """One mesh per ITU material (keys sorted): boxes in the spec's object order, then prisms in theirs."""
    groups: dict[str, list[trimesh.Trimesh]] = {}
    for box in spec.objects:
        groups.setdefault(box.material, []).append(box_mesh(box))
    for prism in spec.prisms:
        groups.setdefault(prism.material, []).append(prism_mesh(prism))
    out = {}
    for material in sorted(groups):
        parts = groups[material]
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
    lines = [
        '<scene version="2.1.0">',
        "",
        f"<!-- dtradar scene {spec.name} (spec sha256 {spec.digest()}) -->",
        "",
        "<!-- Materials -->",
        "",
    ]
    for material in meshes:
        lines += [
            f'\t<bsdf type="itu-radio-material" id={quoteattr("itu_" + material)}>',
            f'\t\t<string name="type" value={quoteattr(material)}/>',
            f'\t\t<float name="thickness" value="{material_thickness(material)!r}"/>',
            "\t</bsdf>",
        ]
    lines += ["", "<!-- Shapes -->", ""]
    for material, mesh in meshes.items():
        _write_if_changed(out_dir / "meshes" / f"{material}.ply", _ply_bytes(mesh))
        lines += [
            f'\t<shape type="ply" id={quoteattr("mesh-" + material)}>',
            f'\t\t<string name="filename" value={quoteattr(f"meshes/{material}.ply")}/>',
            '\t\t<boolean name="face_normals" value="true"/>',
            f'\t\t<ref id={quoteattr("itu_" + material)} name="bsdf"/>',
            "\t</shape>",
        ]
    lines += ["</scene>", ""]
    text = "\n".join(lines)
    if spec.base is not None:  # built on an external XML: its shapes as they are, our objects added
        text = merged_scene_xml(spec.base, text)
    xml_path = out_dir / "scene.xml"
    _write_if_changed(xml_path, text.encode("utf-8"))
    return xml_path
