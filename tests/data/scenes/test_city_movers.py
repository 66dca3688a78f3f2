"""Movers of a city's moving twin: a lane through a building fails even when both its ends are on the street, a lane
on the street reads with the car's size and mesh, and the quadrant and city options apply as they should. No ray
tracer."""

from __future__ import annotations

import copy

import pytest
import tomllib

from dtradar_data.core.errors import SceneFileError, UnknownNameError
from dtradar_data.scenes import load_moving_scene
from dtradar_data.scenes.city.document import parse_city
from dtradar_data.scenes.city.reader import city_file, city_moving_scene


# ------------------------------------------------------------------------------------------- city lanes
@pytest.fixture(scope="module")
def dallas_doc() -> dict:
    return tomllib.loads(city_file("dallas").read_text(encoding="utf-8"))


def _dallas_moving(data: dict, **mover):
    data = copy.deepcopy(data)
    car = {"name": "car_99", "kind": "car", "speed_mps": 5.0} | mover
    data["moving"] = {"quadrant": "q3", "description": "one car", "dt_s": 2.0, "mover": [car]}
    return city_moving_scene(parse_city(data), "q3")


def test_a_lane_through_a_building_fails_even_when_both_its_ends_are_on_the_street(dallas_doc):
    # building_050 spans x 61.8 .. 70.3 m at y = 155.4 m; both ends are more than 3 m from every building
    with pytest.raises(SceneFileError) as e:
        _dallas_moving(dallas_doc, waypoints=[[53.5, 155.4], [78.5, 155.4]], mode="back-and-forth")
    assert "dallas.toml: [moving] mover 'car_99'" in str(e.value)
    assert "runs into building 'building_050'" in str(e.value)
    with pytest.raises(SceneFileError, match=r"waypoints\[1\] \(66, 155.4\) is inside building 'building_050'"):
        _dallas_moving(dallas_doc, waypoints=[[53.5, 155.4], [66.0, 155.4]])


def test_a_lane_on_the_street_reads_with_the_cars_size_and_mesh(dallas_doc):
    moving = _dallas_moving(dallas_doc, waypoints=[[3.36, 73.82], [211.98, 131.67]], mode="back-and-forth")
    box = moving.spec_at(0).objects[-1]
    assert (box.width_m, box.length_m, box.mesh) == (4.4, 1.8, "sionna:low_poly_car")


def test_a_quadrant_without_movers_names_the_one_with_them():
    with pytest.raises(UnknownNameError, match="dallas-q3/moving"):
        load_moving_scene("dallas-q1")
    with pytest.raises(UnknownNameError, match="no moving twin"):
        load_moving_scene("houston-q1")


@pytest.mark.parametrize(
    "quadrant,needle", [(None, "missing field 'quadrant'"), ("q5", "quadrant 'q5' is not a quadrant of the city")]
)
def test_a_city_moving_section_must_name_its_quadrant(dallas_doc, quadrant, needle):
    data = copy.deepcopy(dallas_doc)
    data["moving"].pop("quadrant")
    if quadrant is not None:
        data["moving"]["quadrant"] = quadrant
    with pytest.raises(SceneFileError, match=needle):
        city_moving_scene(parse_city(data), "q3")


def test_the_city_options_apply_to_a_moving_city_and_not_to_a_moving_room():
    moving = load_moving_scene("dallas-q3", cell_m=8.0)
    assert moving.base.grid.cell_m == 8.0 and moving.dt_s == 2.0  # dallas.toml sets its step
    with pytest.raises(SceneFileError, match="--cell-m apply to city scenes only"):
        load_moving_scene("cubicle", cell_m=1.0)
