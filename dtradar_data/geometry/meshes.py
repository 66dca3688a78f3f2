"""Triangle meshes of a :class:`~dtradar_data.scenes.model.SceneSpec` and the Sionna/Mitsuba scene files.

trimesh + numpy only: this module never imports Sionna or Mitsuba, so it tests without them.

- :func:`material_meshes` builds each box as a closed 12-triangle mesh with outward normals and concatenates the
  boxes of one ITU material into one mesh (vertices are *not* welded across boxes, so every box stays a closed
  2-manifold even where two boxes touch).
- :func:`write_mitsuba_scene` writes ``meshes/<material>.ply`` (binary little endian, written by hand so the bytes
  depend only on the spec) and ``scene.xml`` in the Sionna RT 2.x format.
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh

from dtradar_data.scenes.model import Box, SceneSpec

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
