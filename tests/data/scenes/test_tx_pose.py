"""The antenna-pose-error twin: the transmitter moved by exactly the offset and turned by exactly the angle, seeded,
under its own name, everything else unchanged; bad settings fail with a typed error and a hint."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import tomllib

from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError, SceneFileError
from dtradar_data.core.ids import SCENE_RE, TX_POSE_SUFFIX, parse_id
from dtradar_data.scenes import available_scenes, builtin_names, load_scene_spec
from dtradar_data.scenes.indoor.reader import parse_room
from dtradar_data.scenes.tx_pose import orientation_matrix, tx_orientation_deg, tx_pose_error

TOL = 1e-5  # the new pose is rounded to 1e-6 m and 1e-6 degrees


@pytest.fixture(scope="module")
def cubicle():
    return load_scene_spec("cubicle", "blueprint")


def _boresight(tx) -> np.ndarray:
    return orientation_matrix(*tx_orientation_deg(tx))[:, 0]


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(u, v)), float(np.dot(u, v))))


def _frame_turn_deg(tx0, tx1) -> float:
    """The angle of the rotation that takes one antenna frame to the other (the whole array, not only its boresight)."""
    r = orientation_matrix(*tx_orientation_deg(tx1)) @ orientation_matrix(*tx_orientation_deg(tx0)).T
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2))))


@pytest.mark.parametrize("seed", [0, 1, 7, 123])
def test_the_transmitter_moves_exactly_the_offset_horizontally_and_turns_exactly_the_angle(cubicle, seed):
    twin = tx_pose_error(cubicle, offset_m=0.5, angle_deg=5.0, seed=seed)
    before, after = np.array(cubicle.tx.position_m), np.array(twin.tx.position_m)
    assert after[2] == before[2], "the height is kept"
    assert math.hypot(*(after - before)[:2]) == pytest.approx(0.5, abs=TOL)
    assert _angle_deg(_boresight(cubicle.tx), _boresight(twin.tx)) == pytest.approx(5.0, abs=TOL)
    assert _frame_turn_deg(cubicle.tx, twin.tx) == pytest.approx(5.0, abs=TOL), "the array turns 5 deg, no more"


def test_the_look_at_point_lies_along_the_new_boresight_at_the_original_distance(cubicle):
    twin = tx_pose_error(cubicle, seed=3)
    d0 = np.subtract(cubicle.tx.look_at_m, cubicle.tx.position_m)
    d1 = np.subtract(twin.tx.look_at_m, twin.tx.position_m)
    assert np.linalg.norm(d1) == pytest.approx(np.linalg.norm(d0), abs=TOL)
    assert _angle_deg(d1, _boresight(twin.tx)) < 1e-4  # both ends rounded to 1e-6 m, 2.9 m apart
    assert _angle_deg(d0, d1) == pytest.approx(5.0, abs=1e-4)


def test_a_ceiling_access_point_pointing_straight_down_is_tilted_off_the_vertical(cubicle):
    assert np.allclose(_boresight(cubicle.tx), [0, 0, -1])
    twin = tx_pose_error(cubicle, angle_deg=5.0, seed=0)
    assert _angle_deg(_boresight(twin.tx), np.array([0.0, 0.0, -1.0])) == pytest.approx(5.0, abs=TOL)


def test_a_city_transmitter_is_moved_and_turned_and_stays_out_of_every_building():
    from shapely.geometry import Point, Polygon

    spec = load_scene_spec("dallas-q3", "blueprint")
    twin = tx_pose_error(spec, offset_m=0.5, angle_deg=5.0, seed=0)
    assert twin.name == "dallas-q3-txpose/blueprint"
    assert math.dist(spec.tx.position_m, twin.tx.position_m) == pytest.approx(0.5, abs=TOL)
    assert _frame_turn_deg(spec.tx, twin.tx) == pytest.approx(5.0, abs=TOL)
    p = Point(twin.tx.position_m[:2])
    assert not any(Polygon(b.exterior, b.holes).covers(p) for b in twin.prisms if b.top_m >= twin.tx.position_m[2])
    assert twin.prisms == spec.prisms and twin.provenance["city"] == "dallas"
    assert twin.rt_defaults == spec.rt_defaults, "the outdoor ray-tracing defaults travel with the twin"


def test_a_transmitter_with_sionnas_default_orientation_turns_away_from_plus_x(tiny_room):
    room = _tiny_room(tiny_room)
    assert room.tx.look_at_m is None
    twin = tx_pose_error(room, offset_m=0.3, angle_deg=5.0, seed=0)
    assert _angle_deg(_boresight(twin.tx), np.array([1.0, 0.0, 0.0])) == pytest.approx(5.0, abs=TOL)
    assert np.linalg.norm(np.subtract(twin.tx.look_at_m, twin.tx.position_m)) == pytest.approx(1.0, abs=TOL)
    assert twin.provenance["tx_pose_error"]["original"]["look_at_m"] is None


def test_the_same_seed_gives_the_same_twin_and_other_seeds_give_other_poses(cubicle):
    a = tx_pose_error(cubicle, seed=0)
    assert tx_pose_error(cubicle, seed=0) == a and a.digest() == tx_pose_error(cubicle, seed=0).digest()
    others = [tx_pose_error(cubicle, seed=s).tx for s in range(1, 6)]
    assert len({t.position_m for t in [a.tx, *others]}) == 6
    assert len({t.orientation_deg for t in [a.tx, *others]}) == 6


def test_both_variants_of_a_scene_get_the_same_pose(cubicle):
    dynamic = load_scene_spec("cubicle", "dynamic")
    assert tx_pose_error(cubicle, seed=4).tx == tx_pose_error(dynamic, seed=4).tx


def test_only_the_transmitter_name_and_description_change(cubicle):
    twin = tx_pose_error(cubicle)
    assert twin.grid == cubicle.grid and twin.objects == cubicle.objects and twin.room == cubicle.room
    assert (twin.rx_height_m, twin.robot_height_m, twin.variant) == (
        cubicle.rx_height_m,
        cubicle.robot_height_m,
        cubicle.variant,
    )
    same_array = ("num_rows", "num_cols", "pattern", "polarization", "power_dbm")
    assert all(getattr(twin.tx, k) == getattr(cubicle.tx, k) for k in same_array)
    changed = {f.name for f in dataclasses.fields(cubicle) if getattr(twin, f.name) != getattr(cubicle, f.name)}
    assert changed == {"scene", "title", "description", "tx", "provenance"}
    assert twin.digest() != cubicle.digest()


def test_the_twin_is_named_scene_txpose_and_can_never_take_a_built_in_name(cubicle):
    twin = tx_pose_error(cubicle)
    assert twin.scene == "cubicle-txpose" and twin.name == "cubicle-txpose/blueprint"
    assert SCENE_RE.fullmatch(twin.scene) and parse_id("cubicle-txpose/blueprint@v0").scene == "cubicle-txpose"
    assert not any(s.endswith(TX_POSE_SUFFIX) for s in available_scenes())
    assert not any(n.split("/")[0].endswith(TX_POSE_SUFFIX) for n in builtin_names())


def test_a_scene_file_may_not_take_the_reserved_suffix(tiny_room):
    with pytest.raises(SceneFileError, match="txpose") as err:
        _tiny_room(tiny_room.replace('name = "tiny-room"', 'name = "cubicle-txpose"'))
    assert "--tx-pose-error" in str(err.value)


def test_the_description_and_provenance_say_how_the_twin_was_made(cubicle):
    twin = tx_pose_error(cubicle, offset_m=0.5, angle_deg=5.0, seed=2)
    rec = twin.provenance["tx_pose_error"]
    assert rec["scene"] == "cubicle" and (rec["offset_m"], rec["angle_deg"], rec["seed"]) == (0.5, 5.0, 2)
    assert rec["original"]["position_m"] == list(cubicle.tx.position_m)
    assert rec["original"]["look_at_m"] == list(cubicle.tx.look_at_m)
    assert rec["perturbed"]["position_m"] == list(twin.tx.position_m)
    assert twin.description.startswith(cubicle.description)
    assert "0.5 m" in twin.description and "5 deg" in twin.description and "seed 2" in twin.description
    assert cubicle.provenance == {}, "the original spec is untouched"


def test_a_move_that_would_leave_the_room_tries_the_next_seeded_direction(tiny_room):
    room = _tiny_room(tiny_room)  # 2 x 1.5 m, TX at its centre (1.0, 0.75)
    for seed in range(20):
        twin = tx_pose_error(room, offset_m=0.9, angle_deg=1.0, seed=seed)
        x, y, _ = twin.tx.position_m
        assert 0 < x < 2.0 and 0 < y < 1.5
    tried = [
        tx_pose_error(room, offset_m=0.9, seed=s).provenance["tx_pose_error"]["directions_tried"] for s in range(20)
    ]
    assert max(tried) > 1, "some seeds' first direction leaves the 1.5 m deep room"


def test_a_move_that_always_leaves_the_room_is_a_typed_error(tiny_room):
    room = _tiny_room(tiny_room)
    with pytest.raises(InvalidCoordinatesError, match="outside the room") as err:
        tx_pose_error(room, offset_m=3.0)
    assert "smaller offset" in err.value.hint


@pytest.mark.parametrize(
    "offset,angle",
    [(-0.5, 5.0), (float("nan"), 5.0), (float("inf"), 5.0), (0.5, -5.0), (0.5, float("nan")), (0.5, 90.0), (0.5, 120)],
)
def test_a_negative_or_nan_offset_or_angle_or_a_right_angle_is_a_typed_error_with_a_hint(cubicle, offset, angle):
    with pytest.raises(InvalidSettingError, match="--tx-pose-error") as err:
        tx_pose_error(cubicle, offset_m=offset, angle_deg=angle)
    assert err.value.hint


def test_a_zero_error_keeps_the_pose_but_still_names_the_twin(cubicle):
    twin = tx_pose_error(cubicle, offset_m=0.0, angle_deg=0.0)
    assert twin.tx.position_m == cubicle.tx.position_m
    assert np.allclose(twin.tx.look_at_m, cubicle.tx.look_at_m, atol=TOL)
    assert _frame_turn_deg(cubicle.tx, twin.tx) == pytest.approx(0.0, abs=1e-3)
    assert twin.scene == "cubicle-txpose"


def test_a_pose_twin_is_not_perturbed_twice(cubicle):
    with pytest.raises(InvalidSettingError, match="already"):
        tx_pose_error(tx_pose_error(cubicle))


def test_the_orientation_matches_what_sionnas_look_at_gives_an_unperturbed_transmitter(cubicle):
    # Sionna: look_at sets (azimuth, zenith - 90 deg, 0), azimuth 0 for a vertical direction
    assert tx_orientation_deg(cubicle.tx) == pytest.approx((0.0, 90.0, 0.0))
    assert np.allclose(orientation_matrix(0.0, 90.0, 0.0)[:, 0], [0, 0, -1])
    spec = load_scene_spec("dallas-q3", "blueprint")
    d = np.subtract(spec.tx.look_at_m, spec.tx.position_m)
    assert _angle_deg(_boresight(spec.tx), d) < 1e-9


def _tiny_room(text: str):
    return parse_room(tomllib.loads(text), "blueprint", origin="tiny.toml")
