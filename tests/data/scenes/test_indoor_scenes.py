"""Scene model: the paper's two indoor twins load with the right objects, and bad scene files fail clearly."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidCoordinatesError, SceneFileError, UnknownNameError
from dtradar_data.core.ids import VARIANTS
from dtradar_data.scenes import available_scenes, load_scene_spec, scene_file
from dtradar_data.scenes.indoor.reader import load_room_file as load_scene_file
from dtradar_data.scenes.indoor.reader import parse_room as parse_scene
from dtradar_data.scenes.materials import ITU_MATERIALS, material_valid_at
from dtradar_data.scenes.model import Box

# DT-RaDaR Sec. V-A (the object counts are in docs/scenes.md), plus the room structure we generate (4 walls, floor,
# ceiling).
STRUCTURE = {"wall": 4, "floor": 1, "ceiling": 1}
PAPER_COUNTS = {
    ("cubicle", "blueprint"): {"chair": 11, "cubicle": 7, "table": 1},
    ("cubicle", "dynamic"): {"chair": 12, "cubicle": 7, "table": 1, "person": 2},
    ("meeting", "blueprint"): {"chair": 10, "table": 4, "board": 1, "rack": 2, "tv": 1, "monitor": 2},
    ("meeting", "dynamic"): {
        "chair": 12,
        "table": 4,
        "board": 1,
        "rack": 2,
        "tv": 1,
        "monitor": 2,
        "laptop": 2,
        "boxes": 1,
    },
}
PAPER_MATERIALS = {
    "cubicle": {"chair": "wood", "cubicle": "metal", "wall": "brick", "floor": "concrete"},
    "meeting": {
        "chair": "wood",
        "table": "wood",
        "board": "wood",
        "rack": "wood",
        "tv": "metal",
        "monitor": "metal",
        "wall": "brick",
        "floor": "concrete",
    },
}
PAPER_GRIDS = {"cubicle": (18, 42), "meeting": (40, 38)}  # (ny, nx): paper's 42 x 18 and 38 x 40
# Objects re-oriented in each dynamic twin (paper: 3 chairs in the lab, 2 in the meeting room).
REORIENTED = {"cubicle": 3, "meeting": 2}


def test_both_indoor_scenes_from_the_paper_are_available():
    assert {"cubicle", "meeting"} <= set(available_scenes())


@pytest.mark.parametrize("scene,variant", sorted(PAPER_COUNTS))
def test_each_variant_has_exactly_the_papers_object_counts(scene, variant):
    spec = load_scene_spec(scene, variant)
    assert spec.count_by_kind() == {**STRUCTURE, **PAPER_COUNTS[scene, variant]}
    assert spec.name == f"{scene}/{variant}"
    assert spec.grid.shape == PAPER_GRIDS[scene]


@pytest.mark.parametrize("scene", ["cubicle", "meeting"])
def test_objects_use_the_papers_materials(scene):
    spec = load_scene_spec(scene, "dynamic")
    for box in spec.objects:
        if box.kind in PAPER_MATERIALS[scene]:
            assert box.material == PAPER_MATERIALS[scene][box.kind], box.name
        assert box.material in ITU_MATERIALS
        assert material_valid_at(box.material, 2.4e9), f"{box.material} undefined at the paper's 2.4 GHz"


@pytest.mark.parametrize("scene", ["cubicle", "meeting"])
def test_dynamic_twin_is_the_blueprint_plus_the_listed_changes(scene):
    blue = {b.name: b for b in load_scene_spec(scene, "blueprint").objects}
    dyn = {b.name: b for b in load_scene_spec(scene, "dynamic").objects}
    assert set(blue) <= set(dyn)
    added = {n: dyn[n].kind for n in set(dyn) - set(blue)}
    before, after = PAPER_COUNTS[scene, "blueprint"], PAPER_COUNTS[scene, "dynamic"]
    expected_added = {k: v - before.get(k, 0) for k, v in after.items()}
    assert sorted(added.values()) == sorted(k for k, v in expected_added.items() for _ in range(v))
    changed = [n for n in blue if dyn[n] != blue[n]]
    assert len(changed) == REORIENTED[scene]
    for n in changed:
        assert dyn[n].kind == "chair" and dyn[n].yaw_deg != blue[n].yaw_deg
        # Only placement changes; size and material stay.
        same = ("kind", "material", "width_m", "length_m", "height_m")
        assert all(getattr(dyn[n], f) == getattr(blue[n], f) for f in same)


@pytest.mark.parametrize("scene", ["cubicle", "meeting"])
def test_transmitter_is_the_papers_ceiling_array(scene):
    spec = load_scene_spec(scene, "blueprint")
    tx = spec.tx
    assert (tx.num_rows, tx.num_cols, tx.pattern, tx.polarization) == (8, 2, "tr38901", "VH")
    assert spec.room is not None and spec.room.height_m - 0.5 < tx.position_m[2] < spec.room.height_m
    assert any(b.kind == "ceiling" for b in spec.objects)
    assert 0 < spec.rx_height_m < tx.position_m[2]


def test_spec_dict_is_json_canonical_and_the_digest_identifies_the_variant():
    a, b = load_scene_spec("cubicle", "blueprint"), load_scene_spec("cubicle", "blueprint")
    d = a.to_dict()
    assert json.loads(json.dumps(d)) == d
    assert d["grid"] == a.grid.to_dict() and len(d["objects"]) == len(a.objects)
    assert a.digest() == b.digest() and len(a.digest()) == 64
    assert a.digest() != load_scene_spec("cubicle", "dynamic").digest()


def test_digest_ignores_how_numbers_are_written(tmp_path):
    text = scene_file("cubicle").read_text()
    p = tmp_path / "cubicle.toml"
    p.write_text(text.replace("x_m = 1.5\ny_m = 8.05", "x_m = 1.50\ny_m = 8.050", 1).replace("nx = 42", "nx = 0x2a"))
    assert p.read_text() != text
    assert load_scene_file(p, "blueprint").digest() == load_scene_spec("cubicle", "blueprint").digest()


def test_grid_maps_points_to_cells_and_rejects_points_outside():
    g = load_scene_spec("cubicle", "blueprint").grid
    xs, ys = g.centres()
    assert xs.shape == (42,) and ys.shape == (18,) and xs[0] == 0.25 and math.isclose(xs[-1], 20.75)
    assert g.index_of(0.25, 0.25) == (0, 0)
    assert g.index_of(xs[7], ys[5]) == (7, 5)
    assert g.index_of(21.0, 9.0) == (41, 17)  # the far edge belongs to the last cell
    with pytest.raises(InvalidCoordinatesError, match="outside the grid"):
        g.index_of(21.3, 1.0)
    with pytest.raises(InvalidCoordinatesError):
        g.index_of(-0.01, 1.0)


def test_box_corners_rotate_counter_clockwise():
    b = Box("b", "table", "wood", 1.0, 2.0, width_m=2.0, length_m=1.0, height_m=0.75, yaw_deg=90.0)
    c = b.corners()
    assert np.allclose(c.min(axis=0), [0.5, 1.0]) and np.allclose(c.max(axis=0), [1.5, 3.0])
    assert np.allclose(c[0], [1.5, 1.0])  # local (-1, -0.5) turned by +90 deg


def test_unknown_scene_name_suggests_the_closest():
    with pytest.raises(UnknownNameError, match="did you mean 'cubicle'"):
        load_scene_spec("cubical", "blueprint")


def test_unknown_variant_suggests_the_closest():
    with pytest.raises(UnknownNameError, match="did you mean 'dynamic'"):
        load_scene_spec("meeting", "dynamc")
    assert VARIANTS == ("blueprint", "dynamic")


# ---------------------------------------------------------------------------------------------------- bad files
GOOD = """
format = 1
[scene]
name = "tiny"
title = "Tiny"
description = "a test room"
source = "test"
licence = "CC0-1.0"
attribution = "nobody"
[room]
width_m = 4.0
length_m = 3.0
height_m = 2.5
wall_thickness_m = 0.1
wall_material = "brick"
floor_material = "concrete"
floor_thickness_m = 0.1
[grid]
cell_m = 0.5
nx = 8
ny = 6
[tx]
position_m = [2.0, 1.5, 2.4]
[robot]
rx_height_m = 1.0
robot_height_m = 1.0
[kinds.chair]
material = "wood"
width_m = 0.5
length_m = 0.5
height_m = 0.9
[[objects]]
name = "chair_01"
kind = "chair"
x_m = 1.0
y_m = 1.0
[[objects]]
name = "table_01"
kind = "table"
material = "wood"
x_m = 3.0
y_m = 2.0
width_m = 1.0
length_m = 0.6
height_m = 0.75
[dynamic]
description = "moved a chair"
[[dynamic.move]]
name = "chair_01"
yaw_deg = 45.0
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(text)
    return p


def test_a_minimal_scene_file_loads_with_defaults(tmp_path):
    spec = load_scene_file(_write(tmp_path, GOOD), "dynamic")
    assert spec.count_by_kind() == {"floor": 1, "wall": 4, "chair": 1, "table": 1}  # no ceiling asked for
    assert spec.grid.to_dict() == {"x0_m": 0.25, "y0_m": 0.25, "cell_m": 0.5, "nx": 8, "ny": 6}
    assert spec.tx.num_rows == 8 and spec.tx.look_at_m is None
    assert {b.name: b.yaw_deg for b in spec.objects}["chair_01"] == 45.0


BAD_CASES = [
    # (what to replace in GOOD, with what, words the message must contain)
    ('name = "chair_01"\nkind', 'name = "chair_01\nkind', ["tiny.toml", "not valid TOML"]),
    ('material = "wood"\nx_m', 'material = "wod"\nx_m', ["table_01", "'wod'", "did you mean 'wood'"]),
    ("length_m = 0.6", "length_m = -0.6", ["table_01", "length_m must be > 0"]),
    ('name = "table_01"', 'name = "chair_01"', ["chair_01", "duplicate name"]),
    ("x_m = 3.0", "x_m = 3.8", ["table_01", "outside the room"]),
    ("height_m = 0.75", "height_m = 0.75\nz_m = 2.0", ["table_01", "outside the room's 0..2.5 m"]),
    ("y_m = 2.0", "y_m = 2.0\ncolour = 'red'", ["table_01", "unknown key 'colour'"]),
    ("y_m = 2.0", "y_m = 2.0\nyaw = 3.0", ["did you mean 'yaw_deg'"]),
    ("x_m = 1.0\ny_m = 1.0", "x_m = 1.0", ["chair_01", "missing field 'y_m'"]),
    ("nx = 8", "nx = 9", ["[grid]", "not inside the room"]),
    ("position_m = [2.0, 1.5, 2.4]", "position_m = [2.0, 1.5, 2.6]", ["[tx]", "outside the room"]),
    ('wall_material = "brick"', 'wall_material = "bricks"', ["[room]", "did you mean 'brick'"]),
    ('name = "chair_01"\nyaw_deg', 'name = "chiar_01"\nyaw_deg', ["dynamic.move[0]", "did you mean 'chair_01'"]),
    ("rx_height_m = 1.0", "rx_height_m = 3.0", ["[robot]", "not below the ceiling"]),
    ("[robot]\n", "[robots]\n", ["unknown key 'robots'"]),
    ("cell_m = 0.5", 'cell_m = "half"', ["cell_m must be a finite number"]),
    ('material = "wood"\nwidth_m = 0.5', 'material = "wood"\nwidth_m = 0', ["[kinds.chair]", "width_m must be > 0"]),
    ("[robot]", 'pattern = "tr3890"\n[robot]', ["[tx]", "did you mean 'tr38901'"]),
]


@pytest.mark.parametrize("old,new,words", BAD_CASES, ids=[c[2][-1][:30] for c in BAD_CASES])
def test_a_bad_scene_file_raises_scene_file_error_naming_the_problem(tmp_path, old, new, words):
    assert old in GOOD
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SceneFileError) as info:
        load_scene_file(path, "dynamic")
    message = str(info.value)
    assert str(path) in message and "how to fix:" in message
    for w in words:
        assert w in message


def test_a_rotation_that_pushes_an_object_through_the_wall_is_caught(tmp_path):
    # 1.0 x 0.6 table centred 0.45 m from the east wall: fits at yaw 90, not at yaw 0.
    text = GOOD.replace("x_m = 3.0", "x_m = 3.65").replace("height_m = 0.75", "height_m = 0.75\nyaw_deg = 90.0")
    assert load_scene_file(_write(tmp_path, text), "blueprint")
    text = GOOD.replace("x_m = 3.0", "x_m = 3.65")
    with pytest.raises(SceneFileError, match="table_01.*outside the room"):
        load_scene_file(_write(tmp_path, text), "blueprint")


def test_a_missing_scene_file_says_which_path(tmp_path):
    with pytest.raises(SceneFileError, match="cannot read"):
        load_scene_file(tmp_path / "nope.toml", "blueprint")


def test_parse_scene_accepts_an_in_memory_document():
    import tomllib

    spec = parse_scene(tomllib.loads(GOOD), "blueprint", origin="memory")
    assert spec.scene == "tiny" and spec.variant == "blueprint"
    with pytest.raises(SceneFileError, match="memory"):
        data = tomllib.loads(GOOD)
        data["objects"][0]["width_m"] = 0
        parse_scene(data, "blueprint", origin="memory")
