"""Movers and moving twins: a mover walks its waypoints at constant speed, a moving twin is its base scene plus the
movers every step, and every mistake in a [moving] section fails when read, naming the mover. No ray tracer."""

from __future__ import annotations

import copy
import math
import re

import pytest

from dtradar_data.core.errors import InvalidSettingError, SceneFileError, UnknownNameError
from dtradar_data.scenes import build_targets, load_moving_scene, load_scene_spec, scene_file
from dtradar_data.scenes.indoor.reader import parse_moving_room, parse_room
from dtradar_data.scenes.model import Box, SceneSpec
from dtradar_data.scenes.mover import MOVER_MESHES, Mover
from dtradar_data.scenes.moving_scene import (
    DEFAULT_MAX_SNAPSHOTS,
    MAX_SNAPSHOTS,
    ROBOT_SPEED_MPS,
    MovingScene,
    common_snapshots,
)
from dtradar_data.scenes.moving_section import MOVER_KINDS

# A 6 m x 4 m room (0.5 m cells, 12 x 8) with a table in the middle and a shelf high on the north wall.
ROOM = {
    "format": 1,
    "scene": {
        "name": "walk-room",
        "title": "Walk room",
        "description": "a table to walk round",
        "source": "test",
        "licence": "CC0-1.0",
        "attribution": "nobody",
    },
    "room": {
        "width_m": 6.0,
        "length_m": 4.0,
        "height_m": 3.0,
        "wall_thickness_m": 0.2,
        "wall_material": "brick",
        "floor_material": "concrete",
        "floor_thickness_m": 0.1,
        "ceiling_material": "concrete",
        "ceiling_thickness_m": 0.1,
    },
    "grid": {"cell_m": 0.5, "nx": 12, "ny": 8},
    "tx": {"position_m": [3.0, 2.0, 2.9]},
    "robot": {"rx_height_m": 1.0, "robot_height_m": 1.0},
    "objects": [
        {"name": "table_01", "kind": "table", "material": "wood", "x_m": 3.0, "y_m": 2.0}
        | {"width_m": 1.0, "length_m": 1.0, "height_m": 0.75},
        {"name": "shelf_01", "kind": "shelf", "material": "wood", "x_m": 3.0, "y_m": 3.85, "z_m": 2.0}
        | {"width_m": 2.0, "length_m": 0.3, "height_m": 0.4},
    ],
    "dynamic": {
        "description": "a chair by the table",
        "add": [
            {"name": "chair_01", "kind": "chair", "material": "wood", "x_m": 4.5, "y_m": 2.0}
            | {"width_m": 0.5, "length_m": 0.5, "height_m": 0.9}
        ],
    },
    "moving": {
        "description": "one person round the table",
        "mover": [
            {"name": "walker_01", "kind": "person", "speed_mps": 1.0, "waypoints": [[1, 1], [5, 1], [5, 3], [1, 3]]}
        ],
    },
}


def _room(**moving) -> dict:
    doc = copy.deepcopy(ROOM)
    doc["moving"] |= moving
    return doc


def _walker(**fields) -> dict:
    return {**ROOM["moving"]["mover"][0], **fields}


def _fails(doc: dict, *needles: str) -> str:
    with pytest.raises(SceneFileError) as e:
        parse_moving_room(doc, origin="walk.toml")
    text = str(e.value)
    for needle in needles:
        assert needle in text, text
    assert "how to fix" in text
    return text


def _mover(**fields) -> Mover:
    base = {
        "name": "m",
        "kind": "person",
        "material": "wet_ground",
        "width_m": 0.3,
        "length_m": 0.5,
        "height_m": 1.75,
        "speed_mps": 2.0,
        "waypoints": ((0, 0), (4, 0), (4, 2), (0, 2)),
    }
    return Mover(**(base | fields))


# ------------------------------------------------------------------------------------------- kinematics
@pytest.mark.parametrize(
    "t,expected",
    [
        (0.0, (0, 0, 0)),
        (1.0, (2, 0, 0)),
        (2.0, (4, 0, 90)),  # on a waypoint it already faces the next segment
        (2.5, (4, 1, 90)),
        (4.0, (2, 2, 180)),
        (5.0, (0, 2, 270)),
        (5.5, (0, 1, 270)),
        (6.0, (0, 0, 0)),  # one period: 12 m at 2 m/s
        (-1.0, (0, 2, 270)),  # before t = 0 as well
        (61.0, (2, 0, 0)),
    ],
)
def test_a_loop_goes_round_its_waypoints_at_constant_speed_facing_its_way(t, expected):
    x, y, yaw = _mover().position_at(t)
    assert (x, y, yaw) == pytest.approx(expected, abs=1e-9)


def test_a_loop_goes_back_to_its_first_waypoint_and_its_period_is_its_length_over_its_speed():
    m = _mover()
    assert m.path_length_m == pytest.approx(12.0)
    assert m.period_s == pytest.approx(6.0)
    assert m.route == ((0, 0), (4, 0), (4, 2), (0, 2), (0, 0))


@pytest.mark.parametrize(
    "t,expected",
    [(0, (0, 0, 0)), (3, (3, 0, 90)), (7, (3, 4, 270)), (10, (3, 1, 270)), (11, (3, 0, 180)), (13, (1, 0, 180))]
    + [(14, (0, 0, 0))],
)
def test_back_and_forth_walks_to_the_last_waypoint_and_back_the_same_way(t, expected):
    m = _mover(waypoints=((0, 0), (3, 0), (3, 4)), mode="back-and-forth", speed_mps=1.0)
    assert m.period_s == pytest.approx(14.0)  # twice the 7 m path
    assert m.position_at(t) == pytest.approx(expected, abs=1e-9)


def test_a_start_offset_shifts_the_mover_along_its_route():
    late = _mover(start_offset_s=1.5)
    for t in (0.0, 0.7, 4.2):
        assert late.position_at(t) == pytest.approx(_mover().position_at(t + 1.5))


def test_two_waypoints_make_the_same_route_as_a_loop_or_back_and_forth():
    loop = _mover(waypoints=((0, 0), (5, 0)))
    there_and_back = _mover(waypoints=((0, 0), (5, 0)), mode="back-and-forth")
    assert loop.period_s == there_and_back.period_s == pytest.approx(5.0)
    assert all(loop.position_at(t) == pytest.approx(there_and_back.position_at(t)) for t in (0, 1, 2.5, 3, 4.9))


def test_box_at_is_the_mover_as_a_box_named_after_it_where_it_is_facing_its_way():
    car = _mover(name="car_01", kind="car", material="metal", width_m=4.4, length_m=1.8, height_m=1.5)
    car = Mover(**{**car.__dict__, "mesh": "sionna:low_poly_car"})
    box = car.box_at(2.5)
    assert box == Box(
        name="car_01",
        kind="car",
        material="metal",
        x_m=4.0,
        y_m=1.0,
        width_m=4.4,  # along its way: local x is where it drives, as the car mesh faces
        length_m=1.8,
        height_m=1.5,
        z_m=0.0,
        yaw_deg=90.0,
        mesh="sionna:low_poly_car",
    )


def test_a_time_that_is_not_a_finite_number_names_the_mover():
    with pytest.raises(SceneFileError, match="mover 'm': time nan"):
        _mover().position_at(float("nan"))


@pytest.mark.parametrize(
    "fields,needle",
    [
        ({"waypoints": ((0, 0),)}, "needs at least 2 waypoints, has 1"),
        ({"waypoints": ((0, 0), (0, 0))}, "waypoints[0] and waypoints[1] are the same point"),
        ({"speed_mps": 0.0}, "speed_mps = 0.0 must be a finite number > 0"),
        ({"length_m": math.nan}, "length_m = nan must be a finite number > 0"),
        ({"mode": "pingpong"}, "mode 'pingpong' is not a mode"),
        ({"material": "flesh"}, "material 'flesh' is not an ITU material"),
        ({"mesh": "car.ply"}, "mesh 'car.ply' is not a bundled mesh"),
    ],
)
def test_a_mover_made_in_python_is_checked_too(fields, needle):
    with pytest.raises(SceneFileError, match=f"^mover 'm': {re.escape(needle)}"):
        _mover(**fields)


def test_a_moving_scene_made_in_python_checks_its_movers_against_its_base():
    base = parse_room(ROOM, "blueprint")
    assert MovingScene(base, (_mover(waypoints=((1, 1), (5, 1))),), 1.0, 4).snapshots == 4
    with pytest.raises(SceneFileError, match=r"mover 'm': waypoints\[1\] \(9, 1\) is outside the grid"):
        MovingScene(base, (_mover(waypoints=((1, 1), (9, 1))),), 1.0, 4)
    with pytest.raises(SceneFileError, match="dt_s = 0 must be"):
        MovingScene(base, (_mover(waypoints=((1, 1), (5, 1))),), 0, 4)
    with pytest.raises(SceneFileError, match="more than the 2000"):
        MovingScene(base, (_mover(waypoints=((1, 1), (5, 1))),), 1.0, MAX_SNAPSHOTS + 1)


# ------------------------------------------------------------------------------------------- the moving twin
@pytest.fixture(scope="module")
def walk() -> MovingScene:
    return parse_moving_room(
        _room(
            mover=[
                _walker(),
                # 1 m there and back at 2 m/s: back where it was at every 1 s step
                _walker(name="pacer_01", waypoints=[[0.5, 0.5], [1.5, 0.5]], mode="back-and-forth", speed_mps=2.0),
            ]
        ),
        origin="walk.toml",
    )


def test_the_moving_twin_starts_from_the_blueprint_steps_at_cell_size_over_robot_speed_for_the_common_period(walk):
    assert walk.base == parse_room(ROOM, "blueprint")
    assert walk.base.digest() == parse_room(ROOM, "blueprint").digest()
    assert walk.dt_s == 0.5 / ROBOT_SPEED_MPS == 1.0
    assert walk.snapshots == 12  # lcm(12 s loop, 1 s pacer) in 1 s steps
    assert walk.horizon_s == 12.0
    assert walk.name == "walk-room/moving"
    assert walk.provenance["horizon_from"] == "common period"


def test_spec_at_is_a_static_scene_of_the_bases_objects_plus_every_mover_where_it_is_then(walk):
    spec = walk.spec_at(3)
    assert isinstance(spec, SceneSpec)
    assert spec.variant == "moving"
    assert spec.objects[: len(walk.base.objects)] == walk.base.objects
    assert spec.objects[len(walk.base.objects) :] == (walk.movers[0].box_at(3.0), walk.movers[1].box_at(3.0))
    assert (spec.grid, spec.tx, spec.room, spec.prisms) == (walk.base.grid, walk.base.tx, walk.base.room, ())
    assert spec.objects[-2].x_m == 4.0 and spec.objects[-2].y_m == 1.0
    assert spec.provenance["moving"]["snapshot"] == 3 and spec.provenance["moving"]["t_s"] == 3.0
    assert walk.spec_at(3).digest() == spec.digest() != walk.spec_at(4).digest()


def test_changed_between_lists_the_movers_whose_box_moved_with_both_boxes(walk):
    changes = walk.changed_between(3, 4)
    assert [c.name for c in changes] == ["walker_01"]  # the pacer is back where it was
    assert changes[0].before == walk.spec_at(3).objects[-2]
    assert changes[0].after == walk.spec_at(4).objects[-2]
    assert walk.changed_between(5, 5) == ()
    turned = walk.changed_between(0, 4)[0]  # at (5, 1) the walker turns north
    assert (turned.before.yaw_deg, turned.after.yaw_deg) == (0.0, 90.0)


@pytest.mark.parametrize("k", [-1, 12, 1.0, True])
def test_a_snapshot_outside_the_horizon_is_an_error_that_gives_the_range(walk, k):
    with pytest.raises(SceneFileError, match=r"k = 0 \.\. 11"):
        walk.spec_at(k)


def test_the_digest_is_stable_and_changes_with_the_movers_the_step_and_the_horizon(walk):
    again = parse_moving_room(copy.deepcopy(_room(mover=[_walker(), _walker(name="pacer_01")])))
    assert parse_moving_room(_room()).digest() == parse_moving_room(_room()).digest()
    assert walk.base.digest() in walk.canonical_json()
    digests = {
        walk.digest(),
        again.digest(),
        parse_moving_room(_room()).digest(),
        parse_moving_room(_room(dt_s=0.5)).digest(),
        parse_moving_room(_room(horizon_s=6.0)).digest(),
        parse_moving_room(_room(mover=[_walker(speed_mps=1.5)])).digest(),
    }
    assert len(digests) == 6


def test_a_file_may_set_the_step_the_horizon_and_start_from_the_dynamic_twin():
    moving = parse_moving_room(_room(dt_s=0.25, horizon_s=30.1, base="dynamic"))
    assert (moving.dt_s, moving.snapshots) == (0.25, 120)
    assert moving.provenance["horizon_from"] == "scene file"
    assert moving.base == parse_room(ROOM, "dynamic")
    assert "chair_01" in {b.name for b in moving.spec_at(0).objects}


def test_the_default_horizon_is_capped_when_the_common_period_is_too_long():
    periods = [_mover(waypoints=((0, 0), (n / 2, 0)), speed_mps=1.0) for n in (499, 3)]  # 499 s and 3 s
    assert common_snapshots(periods, 1.0) == DEFAULT_MAX_SNAPSHOTS
    assert common_snapshots(periods[:1], 1.0) == 499
    slow = _walker(name="slow_01", speed_mps=12 / 43)  # the same 12 m loop in 43 s: lcm(12, 43) = 516 steps
    moving = parse_moving_room(_room(mover=[_walker(), slow]))
    assert moving.snapshots == DEFAULT_MAX_SNAPSHOTS
    assert moving.provenance["horizon_from"] == f"capped at {DEFAULT_MAX_SNAPSHOTS} snapshots"


def test_only_the_moving_twin_reads_the_moving_section():
    broken = _room(bogus=1, dt_s=-1)
    assert parse_room(broken, "blueprint") == parse_room(ROOM, "blueprint")
    assert parse_room(broken, "dynamic") == parse_room(ROOM, "dynamic")
    _fails(broken, "[moving]", "unknown key 'bogus'")


def test_a_mover_box_blocks_the_robots_cells_in_a_snapshot():
    from dtradar_data.geometry.occupancy import occupancy

    moving = parse_moving_room(_room())
    assert occupancy(moving.spec_at(0)).sum() > occupancy(moving.base).sum()


def test_the_moving_variant_is_read_by_load_moving_scene_and_refused_where_a_single_scene_is_expected():
    with pytest.raises(InvalidSettingError, match=r"load_moving_scene\('cubicle'\)"):
        load_scene_spec("cubicle", "moving")
    assert build_targets("cubicle", "moving") == [("cubicle", "moving")]  # traced by the moving builder
    with pytest.raises(SceneFileError, match="series of scenes"):
        parse_room(ROOM, "moving")
    with pytest.raises(UnknownNameError, match="did you mean 'moving'"):
        load_scene_spec("cubicle", "movin")
    with pytest.raises(SceneFileError, match="no moving twin"):
        load_moving_scene("sionna:munich")


def test_a_users_room_file_has_a_moving_twin(tmp_path):
    path = tmp_path / "lab.toml"
    path.write_text(scene_file("cubicle").read_text(encoding="utf-8").replace('name = "cubicle"', 'name = "my-lab"'))
    moving = load_moving_scene(path)
    assert moving.name == "my-lab/moving"
    assert [m.name for m in moving.movers] == ["walker_01", "walker_02", "walker_03"]


# ------------------------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    "fields,needles",
    [
        ({"waypoints": [[1, 1]]}, ["moving.mover[0] 'walker_01'", "waypoints has 1 point: a mover needs at least 2"]),
        ({"waypoints": [[1, 1], [1, math.inf]]}, ["'walker_01'", "waypoints", "not a point"]),
        ({"speed_mps": 0}, ["'walker_01'", "speed_mps must be a finite number > 0"]),
        ({"speed_mps": math.nan}, ["'walker_01'", "speed_mps must be a finite number > 0"]),
        ({"width_m": -0.3}, ["'walker_01'", "width_m must be a finite number > 0"]),
        ({"height_m": math.inf}, ["'walker_01'", "height_m must be a finite number > 0"]),
        ({"start_offset_s": math.nan}, ["'walker_01'", "start_offset_s must be a finite number"]),
        ({"mode": "loops"}, ["'walker_01'", "did you mean 'loop'"]),
        ({"speed": 1.0}, ["'walker_01'", "unknown key 'speed'", "did you mean 'speed_mps'"]),
        ({"kind": "persn"}, ["'walker_01'", "kind 'persn' has no default size", "did you mean 'person'"]),
        ({"material": "flesh"}, ["'walker_01'", "not an ITU material"]),
        ({"mesh": "sionna:car"}, ["'walker_01'", "did you mean 'sionna:low_poly_car'"]),
        ({"waypoints": [[1, 1], [5, 1], [5, 1]]}, ["'walker_01'", "waypoints[1] and waypoints[2] are the same"]),
        ({"waypoints": [[1, 1], [5, 1], [5, 3], [1, 1]]}, ["'walker_01'", "the last waypoint repeats the first"]),
        ({"waypoints": [[1, 1], [7, 1]]}, ["mover 'walker_01'", "waypoints[1] (7, 1) is outside the grid [0, 6]"]),
        ({"waypoints": [[1, 1], [3, 2]]}, ["mover 'walker_01'", "waypoints[1] (3, 2) is inside table 'table_01'"]),
        # both waypoints free, the straight line between them through the table
        ({"waypoints": [[1, 2], [5, 2]]}, ["mover 'walker_01'", "from waypoints[0] (1, 2) to waypoints[1] (5, 2)"]),
        # the centre line passes 0.2 m from the table's edge: the person's 0.5 m wide box does not
        ({"waypoints": [[1, 1.3], [5, 1.3]]}, ["mover 'walker_01'", "runs into table 'table_01'", "0.5 m across"]),
        # the shelf hangs at 2 m: a person walks under it, something 2.2 m tall does not
        ({"waypoints": [[1, 3.6], [5, 3.6]], "height_m": 2.2}, ["'walker_01'", "runs into shelf 'shelf_01'"]),
        ({"height_m": 3.5}, ["mover 'walker_01'", "taller than the room"]),
        ({"name": "table_01"}, ["mover 'table_01'", "already has an object named 'table_01'"]),
        ({"name": "wall_north"}, ["mover 'wall_north'", "already has an object named"]),
    ],
)
def test_a_bad_mover_fails_when_read_naming_the_mover_and_the_fix(fields, needles):
    _fails(_room(mover=[_walker(**fields)]), "walk.toml", *needles)


def test_a_person_walks_under_a_shelf_above_its_head():
    moving = parse_moving_room(_room(mover=[_walker(waypoints=[[1, 3.6], [5, 3.6]])]))
    assert moving.movers[0].height_m == MOVER_KINDS["person"][2] < 2.0


def test_a_kind_without_defaults_needs_every_size_and_a_material():
    fields = {"kind": "robot_dog", "width_m": 0.6, "length_m": 0.3, "height_m": 0.5, "material": "metal"}
    assert parse_moving_room(_room(mover=[_walker(**fields)])).movers[0].kind == "robot_dog"
    del fields["material"]
    _fails(_room(mover=[_walker(**fields)]), "'walker_01'", "kind 'robot_dog' has no default size", "material")


def test_two_movers_with_one_name_fail():
    _fails(_room(mover=[_walker(), _walker(waypoints=[[1, 1], [5, 1]])]), "mover 'walker_01'", "two movers")


@pytest.mark.parametrize(
    "moving,needles",
    [
        ({"dt_s": 0}, ["[moving]", "dt_s must be a finite number of seconds > 0"]),
        ({"dt_s": -1.0}, ["[moving]", "dt_s must be a finite number of seconds > 0"]),
        ({"dt_s": math.nan}, ["dt_s must be a finite number"]),
        ({"horizon_s": 1e4}, ["[moving]", f"10000 snapshots, more than the {MAX_SNAPSHOTS}"]),
        ({"horizon_s": 0.2}, ["[moving]", "shorter than one step"]),
        ({"base": "blue"}, ["[moving]", "did you mean 'blueprint'"]),
        ({"mover": []}, ["has no movers"]),
        ({"description": ""}, ["[moving]", "description"]),
    ],
)
def test_bad_moving_settings_fail_naming_the_setting(moving, needles):
    _fails(_room(**moving), "walk.toml", *needles)


def test_a_room_without_a_moving_section_has_no_moving_twin():
    doc = copy.deepcopy(ROOM)
    del doc["moving"]
    _fails(doc, "missing section [moving]")


def test_the_movers_meshes_are_the_bundled_meshes():
    from dtradar_data.geometry.meshes import BUNDLED_MESHES

    assert set(MOVER_MESHES) == set(BUNDLED_MESHES)
