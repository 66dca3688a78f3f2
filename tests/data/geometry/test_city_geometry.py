"""City geometry: extruded footprints and bundled vehicle meshes are closed, sized and placed as the spec says; a
building blocks the cells it mostly covers; surfaces never block. No ray tracer needed."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from dtradar_data.core.grid import Grid
from dtradar_data.geometry.meshes import box_mesh, material_meshes, prism_mesh, write_mitsuba_scene
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.scenes.model import Box, Prism, SceneSpec, TxSpec

L_SHAPE = ((0.0, 0.0), (6.0, 0.0), (6.0, 2.0), (2.0, 2.0), (2.0, 6.0), (0.0, 6.0))
COURTYARD = ((10.0, 0.0), (16.0, 0.0), (16.0, 6.0), (10.0, 6.0))
HOLE = ((12.0, 2.0), (12.0, 4.0), (14.0, 4.0), (14.0, 2.0))  # clockwise


def city(prisms=(), objects=(), cell_m=2.0, nx=8, ny=3):
    return SceneSpec(
        scene="tiny-city",
        variant="blueprint",
        title="t",
        description="d",
        source="s",
        licence="l",
        attribution="a",
        grid=Grid(cell_m / 2, cell_m / 2, cell_m, nx, ny),
        tx=TxSpec(position_m=(8.0, 3.0, 18.0)),
        rx_height_m=1.5,
        robot_height_m=1.5,
        objects=tuple(objects),
        prisms=tuple(prisms),
    )


def test_an_extruded_concave_footprint_is_a_closed_mesh_of_its_area_and_height():
    mesh = prism_mesh(Prism("b", "building", "brick", L_SHAPE, 30.0, z_m=0.0))
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(20.0 * 30.0)
    np.testing.assert_allclose(mesh.bounds, [[0, 0, 0], [6, 6, 30]])


def test_a_courtyard_stays_open_in_the_mesh_and_in_the_occupancy():
    prism = Prism("c", "building", "concrete", COURTYARD, 10.0, holes=(HOLE,))
    mesh = prism_mesh(prism)
    assert mesh.is_watertight and mesh.volume == pytest.approx((36.0 - 4.0) * 10.0)
    blocked = occupancy(city([prism], cell_m=1.0, nx=18, ny=7))
    assert not blocked[2, 12] and not blocked[3, 13]  # inside the hole
    assert blocked[0, 10] and blocked[5, 15]


def test_a_building_blocks_the_cells_it_covers_at_least_half_and_surfaces_never_block():
    # 2 m cells: the building spans x 0..3 (cell 0 whole, cell 1 half) and y 0..6
    building = Prism("b", "building", "glass", ((0.0, 0.0), (3.0, 0.0), (3.0, 6.0), (0.0, 6.0)), 50.0)
    lot = Prism("p", "parking", "concrete", ((6.0, 0.0), (12.0, 0.0), (12.0, 6.0), (6.0, 6.0)), 0.02)
    blocked = occupancy(city([building, lot]))
    assert blocked[:, 0].all() and blocked[:, 1].all() and not blocked[:, 2:].any()
    thin = Prism("t", "building", "glass", ((4.0, 0.0), (4.9, 0.0), (4.9, 6.0), (4.0, 6.0)), 50.0)
    assert not occupancy(city([thin]))[:, 2].any()  # covers 45 % of its cells


def test_a_car_is_sionnas_low_poly_mesh_scaled_into_its_box():
    car = Box(
        "car_01",
        "car",
        "metal",
        x_m=10.0,
        y_m=5.0,
        width_m=4.4,
        length_m=1.8,
        height_m=1.5,
        yaw_deg=90.0,
        mesh="sionna:low_poly_car",
    )
    mesh = box_mesh(car)
    assert mesh.is_watertight
    np.testing.assert_allclose(mesh.bounds, [[10 - 0.9, 5 - 2.2, 0.0], [10 + 0.9, 5 + 2.2, 1.5]], atol=1e-6)
    assert len(mesh.faces) != 12  # not a box
    assert car.to_dict()["mesh"] == "sionna:low_poly_car"
    assert "mesh" not in Box("x", "chair", "wood", 0, 0, 1, 1, 1).to_dict()  # indoor digests unchanged


def test_an_unknown_bundled_mesh_suggests_the_known_ones():
    from dtradar_data.core.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="sionna:low_poly_car"):
        box_mesh(Box("v", "car", "metal", 0, 0, 4, 2, 1.5, mesh="sionna:low_poly_cat"))


def test_a_city_writes_one_mesh_per_material_including_buildings_and_vehicles(tmp_path):
    spec = city(
        [
            Prism("b", "building", "brick", L_SHAPE, 30.0),
            Prism("g", "building", "glass", COURTYARD, 60.0, holes=(HOLE,)),
        ],
        [
            Box("ground", "floor", "concrete", 8, 3, 20, 10, 0.2, z_m=-0.2),
            Box("car_01", "car", "metal", 8, 8, 4.4, 1.8, 1.5, mesh="sionna:low_poly_car"),
        ],
    )
    assert sorted(material_meshes(spec)) == ["brick", "concrete", "glass", "metal"]
    xml = write_mitsuba_scene(spec, tmp_path)
    shapes = ET.parse(xml).getroot().findall("shape")
    assert sorted(s.get("id") for s in shapes) == ["mesh-brick", "mesh-concrete", "mesh-glass", "mesh-metal"]
    first = (tmp_path / "meshes" / "glass.ply").read_bytes()
    write_mitsuba_scene(spec, tmp_path)
    assert (tmp_path / "meshes" / "glass.ply").read_bytes() == first
