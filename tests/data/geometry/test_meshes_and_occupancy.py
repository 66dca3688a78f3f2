"""Geometry: closed per-material meshes, Sionna XML + PLY files, occupancy and connectivity. No Sionna needed."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import tomllib

from dtradar_data.geometry.meshes import box_mesh, material_meshes, material_thickness, write_mitsuba_scene
from dtradar_data.geometry.occupancy import (
    footprints,
    free_components,
    largest_free_component,
    largest_free_component_fraction,
    occupancy,
)
from dtradar_data.scenes import load_scene_spec
from dtradar_data.scenes.indoor.reader import parse_room as parse_scene
from dtradar_data.scenes.model import Box

ALL_VARIANTS = [(s, v) for s in ("cubicle", "meeting") for v in ("blueprint", "dynamic")]

ROOM = """
format = 1
[scene]
name = "box-room"
title = "Box room"
description = "one obstacle"
source = "test"
licence = "CC0-1.0"
attribution = "nobody"
[room]
width_m = 4.0
length_m = 4.0
height_m = 3.0
wall_thickness_m = 0.2
wall_material = "brick"
floor_material = "concrete"
floor_thickness_m = 0.1
ceiling_material = "concrete"
ceiling_thickness_m = 0.1
[grid]
cell_m = 0.5
nx = 8
ny = 8
[tx]
position_m = [2.0, 2.0, 2.9]
[robot]
rx_height_m = 1.0
robot_height_m = 1.0
"""


def _room_with(*objects: dict):
    data = tomllib.loads(ROOM)
    data["objects"] = [
        {"kind": "thing", "material": "wood", "width_m": 0.5, "length_m": 0.5, "height_m": 0.9, **o} for o in objects
    ]
    return parse_scene(data, "blueprint", origin="test")


# ---------------------------------------------------------------------------------------------------- meshes
@pytest.mark.parametrize("scene,variant", ALL_VARIANTS)
def test_one_closed_mesh_per_material_whose_bounds_match_its_boxes(scene, variant):
    spec = load_scene_spec(scene, variant)
    meshes = material_meshes(spec)
    assert list(meshes) == sorted({b.material for b in spec.objects})
    for material, mesh in meshes.items():
        boxes = [b for b in spec.objects if b.material == material]
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert len(mesh.faces) == 12 * len(boxes)
        # Outward normals make every closed box's signed volume positive; the sum is the boxes' volume.
        assert mesh.volume == pytest.approx(sum(b.width_m * b.length_m * b.height_m for b in boxes))
        corners = np.vstack([b.corners() for b in boxes])
        lo = [corners[:, 0].min(), corners[:, 1].min(), min(b.z_m for b in boxes)]
        hi = [corners[:, 0].max(), corners[:, 1].max(), max(b.top_m for b in boxes)]
        assert np.allclose(mesh.bounds, [lo, hi], atol=1e-9)


def test_a_rotated_box_mesh_has_its_size_and_outward_normals():
    b = Box("t", "table", "wood", 1.0, 2.0, width_m=1.8, length_m=0.9, height_m=0.75, z_m=0.1, yaw_deg=30.0)
    m = box_mesh(b)
    assert m.is_watertight and m.volume == pytest.approx(1.8 * 0.9 * 0.75)
    assert np.allclose(m.bounds[:, 2], [0.1, 0.85])
    assert np.allclose(np.sort(m.vertices[:, :2], axis=0), np.sort(np.repeat(b.corners(), 2, axis=0), axis=0))
    # Each face normal points away from the centre.
    centre = np.array([1.0, 2.0, 0.475])
    assert (np.einsum("ij,ij->i", m.face_normals, m.triangles_center - centre) > 0).all()


# ---------------------------------------------------------------------------------------------------- Mitsuba XML
def _ply_counts(path):
    data = path.read_bytes()
    header = data[: data.index(b"end_header\n")].decode("ascii")
    assert "format binary_little_endian 1.0" in header
    counts = {line.split()[1]: int(line.split()[2]) for line in header.splitlines() if line.startswith("element")}
    body = len(data) - data.index(b"end_header\n") - len(b"end_header\n")
    assert body == counts["vertex"] * 12 + counts["face"] * 13  # 3 float32; uchar + 3 int32
    return counts


def test_mitsuba_xml_parses_and_references_one_ply_per_material(tmp_path):
    spec = load_scene_spec("meeting", "dynamic")
    xml_path = write_mitsuba_scene(spec, tmp_path / "out")
    assert xml_path == tmp_path / "out" / "scene.xml"
    root = ET.parse(xml_path).getroot()
    assert root.tag == "scene" and root.get("version") == "2.1.0"
    meshes = material_meshes(spec)
    bsdfs = {b.get("id"): b for b in root.findall("bsdf")}
    assert set(bsdfs) == {f"itu_{m}" for m in meshes}
    for material in meshes:
        b = bsdfs[f"itu_{material}"]
        assert b.get("type") == "itu-radio-material"
        assert b.find("string[@name='type']").get("value") == material
        assert float(b.find("float[@name='thickness']").get("value")) == material_thickness(material) > 0
    shapes = root.findall("shape")
    assert len(shapes) == len(meshes)
    for shape in shapes:
        assert shape.get("type") == "ply"
        ply = xml_path.parent / shape.find("string[@name='filename']").get("value")
        assert ply.is_file()
        assert shape.find("boolean[@name='face_normals']").get("value") == "true"
        material = shape.find("ref[@name='bsdf']").get("id").removeprefix("itu_")
        assert shape.get("id") == f"mesh-{material}"
        counts = _ply_counts(ply)
        assert counts == {"vertex": len(meshes[material].vertices), "face": len(meshes[material].faces)}


def test_writing_the_same_spec_twice_gives_identical_bytes(tmp_path):
    spec = load_scene_spec("cubicle", "dynamic")
    a = write_mitsuba_scene(spec, tmp_path / "a").parent
    b = write_mitsuba_scene(load_scene_spec("cubicle", "dynamic"), tmp_path / "b").parent
    files_a = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files_a == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    assert all((a / f).read_bytes() == (b / f).read_bytes() for f in files_a)
    write_mitsuba_scene(spec, tmp_path / "a")  # rewriting in place changes nothing either
    assert all((a / f).read_bytes() == (b / f).read_bytes() for f in files_a)


def test_blueprint_and_dynamic_write_different_meshes(tmp_path):
    a = write_mitsuba_scene(load_scene_spec("cubicle", "blueprint"), tmp_path / "a").parent
    b = write_mitsuba_scene(load_scene_spec("cubicle", "dynamic"), tmp_path / "b").parent
    assert (a / "meshes/wood.ply").read_bytes() != (b / "meshes/wood.ply").read_bytes()
    assert not (a / "meshes/wet_ground.ply").exists() and (b / "meshes/wet_ground.ply").exists()


# ---------------------------------------------------------------------------------------------------- occupancy
def test_a_box_flush_with_one_cell_blocks_only_that_cell():
    spec = _room_with({"name": "b", "x_m": 1.25, "y_m": 1.75})  # spans exactly x 1.0..1.5, y 1.5..2.0
    blocked = occupancy(spec)
    assert blocked.shape == (8, 8)
    assert np.argwhere(blocked).tolist() == [[3, 2]]  # [iy, ix]
    assert spec.grid.index_of(1.25, 1.75) == (2, 3)


def test_a_rotated_box_blocks_every_cell_its_footprint_touches():
    # 0.5 m square turned 45 deg around a cell centre: its tips poke 0.10 m into the four edge neighbours, but it
    # never reaches the diagonal neighbours (their nearest corner is 0.104 m beyond its edge).
    spec = _room_with({"name": "b", "x_m": 1.25, "y_m": 1.25, "yaw_deg": 45.0})
    assert sorted(map(tuple, np.argwhere(occupancy(spec)))) == [(1, 2), (2, 1), (2, 2), (2, 3), (3, 2)]
    # The same box unrotated but off-centre covers parts of four cells.
    spec = _room_with({"name": "b", "x_m": 1.0, "y_m": 1.0})
    assert sorted(map(tuple, np.argwhere(occupancy(spec)))) == [(1, 1), (1, 2), (2, 1), (2, 2)]


def test_only_objects_within_the_robots_height_block():
    spec = _room_with(
        {"name": "tv", "x_m": 1.25, "y_m": 1.25, "z_m": 1.3, "height_m": 0.8},  # above the 1.0 m robot
        {"name": "rug", "x_m": 2.25, "y_m": 2.25, "height_m": 0.02},  # below the 0.05 m clearance
        {"name": "laptop", "x_m": 3.25, "y_m": 3.25, "z_m": 0.75, "height_m": 0.02},  # on a (missing) table
    )
    assert np.argwhere(occupancy(spec)).tolist() == [[6, 6]]


def test_floor_and_ceiling_never_block_and_walls_outside_the_grid_do_not_either():
    spec = _room_with()
    assert not occupancy(spec).any()
    kinds = [b.kind for b, _ in footprints(spec)]
    assert kinds.count("wall") == 4 and "floor" not in kinds and "ceiling" not in kinds
    assert {"floor", "ceiling"} <= {b.kind for b, _ in footprints(spec, include_structure=True)}


@pytest.mark.parametrize("scene,variant", ALL_VARIANTS)
def test_known_obstacles_block_their_cells_and_the_open_floor_is_free(scene, variant):
    spec = load_scene_spec(scene, variant)
    blocked = occupancy(spec)
    assert blocked.shape == spec.grid.shape
    for box in spec.objects:
        if box.kind in ("chair", "table", "cubicle", "rack", "person", "boxes"):
            ix, iy = spec.grid.index_of(box.x_m, box.y_m)
            assert blocked[iy, ix], box.name
    tv = [b for b in spec.objects if b.kind == "tv"]
    for box in tv:  # mounted above the robot: the floor below it is free
        ix, iy = spec.grid.index_of(box.x_m, box.y_m)
        assert not blocked[iy, ix]
    open_floor = {"cubicle": (5.0, 4.5), "meeting": (1.5, 5.0)}[scene]
    ix, iy = spec.grid.index_of(*open_floor)
    assert not blocked[iy, ix]
    assert 0.1 < blocked.mean() < 0.4  # furnished, not filled


@pytest.mark.parametrize("scene,variant", ALL_VARIANTS)
def test_free_cells_form_one_connected_region_mostly(scene, variant):
    blocked = occupancy(load_scene_spec(scene, variant))
    assert largest_free_component_fraction(blocked) >= 0.9


def test_free_components_are_labelled_largest_first():
    blocked = np.array([[0, 1, 0, 0], [0, 1, 0, 0], [1, 1, 1, 1]], dtype=bool)
    labels = free_components(blocked)
    assert labels.tolist() == [[2, 0, 1, 1], [2, 0, 1, 1], [0, 0, 0, 0]]
    assert largest_free_component(blocked).sum() == 4
    assert largest_free_component_fraction(blocked) == pytest.approx(4 / 6)
    assert largest_free_component_fraction(np.ones((2, 2), dtype=bool)) == 0.0


@pytest.mark.sionna
def test_sionna_loads_the_written_scene_with_one_object_per_itu_material():
    from dtradar_data.core.errors import RayTracerUnavailableError

    try:
        from dtradar_data.rt.tracer import RayTracer
    except (ImportError, RayTracerUnavailableError) as e:  # pragma: no cover - machines without Sionna
        pytest.skip(f"Sionna RT unavailable: {e}")
    spec = load_scene_spec("meeting", "dynamic")
    try:
        tracer = RayTracer(spec)
    except RayTracerUnavailableError as e:  # pragma: no cover
        pytest.skip(f"Sionna RT unavailable: {e}")
    objects = tracer.scene.objects
    assert sorted(objects) == sorted(material_meshes(spec))
    assert {n: o.radio_material.itu_type for n, o in objects.items()} == {m: m for m in objects}
