"""A scene's transmitters: one [tx] table or several [[tx]] tables per scene file, and never inside an object, a
wall, a building or a mover's path. Each mistake is a SceneFileError naming the file and what to do, raised when the
scene is named (no tracer)."""

from __future__ import annotations

import copy

import pytest
import tomllib

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes import load_scene_spec, scene_file
from dtradar_data.scenes.city.document import parse_city
from dtradar_data.scenes.indoor.reader import parse_moving_room, parse_room
from dtradar_data.scenes.transmitters import object_at

# A 6 m x 4 m room with a table in the middle and a transmitter below the ceiling above it.
ROOM = {
    "format": 1,
    "scene": {"name": "tx-room", "title": "Tx room", "description": "a table", "source": "test"}
    | {"licence": "CC0-1.0", "attribution": "nobody"},
    "room": {"width_m": 6.0, "length_m": 4.0, "height_m": 3.0, "wall_thickness_m": 0.2, "wall_material": "brick"}
    | {"floor_material": "concrete", "floor_thickness_m": 0.1},
    "grid": {"cell_m": 0.5, "nx": 12, "ny": 8},
    "tx": {"position_m": [3.0, 2.0, 2.9]},
    "robot": {"rx_height_m": 1.0, "robot_height_m": 1.0},
    "objects": [
        {"name": "table_01", "kind": "table", "material": "wood", "x_m": 3.0, "y_m": 2.0}
        | {"width_m": 1.0, "length_m": 1.0, "height_m": 0.75},
    ],
    "dynamic": {"description": "nothing moved"},
}


def room(**changes) -> dict:
    doc = copy.deepcopy(ROOM)
    doc.update(changes)
    return doc


def refused(doc: dict, *needles: str, variant: str = "blueprint") -> str:
    with pytest.raises(SceneFileError) as e:
        parse_room(doc, variant, origin="room.toml")
    text = str(e.value)
    assert text.startswith("room.toml: ") and "how to fix" in text, text
    for needle in needles:
        assert needle in text, text
    return text


def test_the_room_as_written_loads_and_its_transmitter_is_in_no_object():
    spec = parse_room(room(), "blueprint")
    assert object_at(spec, spec.tx.position_m) is None
    assert object_at(spec, (3.0, 2.0, 0.5)) == "table_01"


def test_several_tx_tables_load_as_transmitter_zero_and_the_more_tx_in_file_order_with_their_names():
    tx = [{"name": "ap1", "position_m": [1.0, 1.0, 2.9]}, {"name": "ap2", "position_m": [5.0, 3.0, 2.9]}]
    spec = parse_room(room(tx=tx), "blueprint")
    assert [t.name for t in spec.transmitters] == ["ap1", "ap2"]
    assert spec.tx.position_m == (1.0, 1.0, 2.9) and spec.more_tx[0].position_m == (5.0, 3.0, 2.9)
    assert spec.to_dict()["more_tx"][0]["name"] == "ap2"


def test_two_transmitters_of_one_name_are_refused_naming_it():
    tx = [{"name": "ap1", "position_m": [1.0, 1.0, 2.9]}, {"name": "ap1", "position_m": [5.0, 3.0, 2.9]}]
    refused(room(tx=tx), "name 'ap1' is given to more than one transmitter", "its own name")


def test_transmitters_with_different_arrays_are_refused_when_the_room_is_read_naming_both_arrays():
    tx = [{"name": "ap1", "position_m": [1.0, 1.0, 2.9]}, {"name": "ap2", "position_m": [5.0, 3.0, 2.9], "num_cols": 1}]
    refused(room(tx=tx), "[[tx]] 'ap2' has another array than [[tx]] 'ap1' (8x1 tr38901 VH vs 8x2 tr38901 VH)")
    tx[1] |= {"num_cols": 2, "pattern": "iso"}
    refused(room(tx=tx), "(8x2 iso VH vs 8x2 tr38901 VH)", "the same num_rows, num_cols, pattern and polarization")


def test_a_single_tx_block_in_double_brackets_is_the_same_scene_as_single_brackets():
    single = parse_room(room(tx=[{"position_m": [3.0, 2.0, 2.9]}]), "blueprint")
    assert single.digest() == parse_room(room(), "blueprint").digest()
    assert "more_tx" not in single.to_dict() and "name" not in single.to_dict()["tx"]


def test_a_second_transmitter_inside_an_object_is_refused_naming_which_transmitter():
    tx = [{"position_m": [1.0, 1.0, 2.9]}, {"name": "low", "position_m": [3.2, 2.1, 0.5]}]
    refused(room(tx=tx), "[[tx]] 'low'", "inside 'table_01'")


def test_an_entry_of_the_tx_array_that_is_not_a_table_is_refused():
    refused(room(tx=[{"position_m": [1.0, 1.0, 2.9]}, 3]), "tx[1] is 3, not a table")


def test_an_empty_tx_array_says_a_scene_needs_a_transmitter():
    refused(room(tx=[]), "holds no transmitter")


def test_no_tx_section_names_the_missing_section():
    doc = room()
    del doc["tx"]
    refused(doc, "missing section [tx]")


def test_a_transmitter_inside_an_object_is_refused_naming_the_object_and_its_extent():
    refused(room(tx={"position_m": [3.2, 2.1, 0.5]}), "inside 'table_01'", "z 0..0.75 m", "blueprint twin")


def test_a_dynamic_change_that_covers_the_transmitter_is_refused_for_the_dynamic_twin_only():
    cabinet = {"name": "cabinet_01", "kind": "shelf", "material": "wood", "x_m": 1.0, "y_m": 1.0}
    cabinet |= {"width_m": 0.6, "length_m": 0.6, "height_m": 2.95}
    doc = room(tx={"position_m": [1.0, 1.0, 2.9]}, dynamic={"description": "a tall cabinet", "add": [cabinet]})
    assert parse_room(doc, "blueprint").tx.position_m == (1.0, 1.0, 2.9)
    refused(doc, "inside 'cabinet_01'", "dynamic twin", variant="dynamic")


def test_a_mover_tall_enough_to_hold_the_transmitter_may_not_walk_through_it():
    walker = {"name": "walker_01", "kind": "person", "speed_mps": 1.0, "waypoints": [[1, 1], [5, 1], [5, 3], [1, 3]]}
    doc = room(tx={"position_m": [1.0, 2.0, 1.5]}, moving={"description": "a walk", "mover": [walker]})
    with pytest.raises(SceneFileError) as e:
        parse_moving_room(doc, origin="room.toml")
    assert "walker_01" in str(e.value) and "through the transmitter at (1, 2, 1.5) m" in str(e.value)
    doc["tx"] = {"position_m": [1.0, 2.0, 2.5]}  # above the walker's 1.75 m: free
    assert parse_moving_room(doc, origin="room.toml").movers[0].name == "walker_01"


def test_a_city_file_with_tx_blocks_is_refused_before_its_quadrants_are_read():
    data = tomllib.loads(scene_file("dallas-q1").read_text())
    data["tx"] = [data["tx"], data["tx"]]
    with pytest.raises(SceneFileError, match=r"(?s)city\.toml: \[\[tx\]\].*more_tx_m"):
        parse_city(data, origin="city.toml")


def test_an_xml_scene_file_with_tx_blocks_loads_every_transmitter_and_refuses_one_tx_option(tmp_path):
    toml = tmp_path / "canyon.toml"
    toml.write_text("""format = 1
[scene]
name = "my-canyon"
title = "My canyon"
[xml]
path = "sionna:simple_street_canyon"
[grid]
x0_m = -20.0
y0_m = -4.0
cell_m = 4.0
nx = 11
ny = 3
[[tx]]
position_m = [0.0, 0.0, 20.0]
[[tx]]
position_m = [10.0, 0.0, 20.0]
""")
    spec = load_scene_spec(toml, "blueprint")
    assert [t.position_m for t in spec.transmitters] == [(0.0, 0.0, 20.0), (10.0, 0.0, 20.0)]
    assert spec.more_tx[0].look_at_m == spec.tx.look_at_m  # both look at the grid's centre
    with pytest.raises(SceneFileError, match=r"--tx places one transmitter, and this scene has 2"):
        load_scene_spec(toml, "blueprint", tx=(1.0, 0.0, 20.0))
    toml.write_text(toml.read_text() + 'polarization = "V"\n')
    with pytest.raises(SceneFileError, match=r"\[\[tx\]\] #2 has another array than \[\[tx\]\] #1 \(8x2 tr38901 V vs"):
        load_scene_spec(toml, "blueprint")


def test_the_built_in_rooms_and_quadrants_keep_their_transmitters_clear():
    for scene in ("cubicle", "meeting", "dallas-q3"):
        for variant in ("blueprint", "dynamic"):
            spec = load_scene_spec(scene, variant)
            assert object_at(spec, spec.tx.position_m) is None, spec.name
