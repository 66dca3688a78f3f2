"""The moving twins of the built-in scene files: they read, their movers walk and drive where the files say, and
adding them changed nothing of the blueprints and dynamic twins (their digests are pinned here)."""

from __future__ import annotations

import math

import pytest

from dtradar_data.core.errors import SceneFileError, UnknownNameError
from dtradar_data.scenes import build_targets, load_moving_scene, load_scene_spec
from dtradar_data.scenes.city.document import read_city_file
from dtradar_data.scenes.city.reader import city_file, city_moving_scene, city_spec
from dtradar_data.scenes.moving_scene import MAX_SNAPSHOTS, ROBOT_SPEED_MPS, MovingScene

# Computed with the code before movers existed (commit 242fba3): the [moving] sections must not change a byte of the
# other variants, or every stored dataset of them would get a new version.
PINNED_DIGESTS = {
    ("cubicle", "blueprint"): "fa031305fb88e505982f9c84c3d6cb8e1536f7c3ba994453f042d7c78a1fdc1c",
    ("cubicle", "dynamic"): "6ebfa19fe182219a1fc6249a7da2f4fec87b7f7045d44400558979025337ea64",
    ("meeting", "blueprint"): "d0fa0bb3d6be53a98ae4d96e7bab7c2746f580304f0e225d3c74bc1b64dcd8a3",
    ("meeting", "dynamic"): "bac023174066245ac4e43bd2f4991f93390420a9d324d0c5fced6307e9e003df",
    ("dallas-q3", "blueprint"): "9ce967b25752b7b2c1e1661e5d7f8fbe481240001741139c50a4aeaeefdfa8fb",
    ("dallas-q3", "dynamic"): "49f72157e05b08006983dd89941bbc4f2de1ec232dfa6c88cea8596a042e9531",
    ("dallas-q1", "blueprint"): "a198858f1a2ad0c6c608d3469aae90905b371c7eadecc1a8d870e1cd51a04d84",
}


@pytest.mark.parametrize("scene,variant", sorted(PINNED_DIGESTS))
def test_the_blueprints_and_dynamic_twins_keep_their_digests(scene, variant):
    assert load_scene_spec(scene, variant).digest() == PINNED_DIGESTS[scene, variant]


# scene -> (movers by kind, dt_s, snapshots)
BUILTIN_MOVING = {
    "cubicle": ({"person": 3}, 0.5 / ROBOT_SPEED_MPS, 16),
    "meeting": ({"person": 2}, 0.25 / ROBOT_SPEED_MPS, 48),
    "dallas-q3": ({"car": 5, "bus": 5}, 2.0, 50),  # dallas.toml sets dt_s: an outdoor robot's 2 m/s per 4 m cell
}


@pytest.fixture(scope="module", params=sorted(BUILTIN_MOVING))
def builtin(request) -> MovingScene:
    return load_moving_scene(request.param)


def test_each_builtin_moving_twin_moves_its_people_or_vehicles_through_its_blueprint(builtin):
    kinds, dt_s, snapshots = BUILTIN_MOVING[builtin.scene]
    counts: dict[str, int] = {}
    for m in builtin.movers:
        counts[m.kind] = counts.get(m.kind, 0) + 1
    assert counts == kinds
    assert (builtin.dt_s, builtin.snapshots) == (dt_s, snapshots)
    assert builtin.base.digest() == PINNED_DIGESTS.get((builtin.scene, "blueprint"), builtin.base.digest())
    assert builtin.base == load_scene_spec(builtin.scene, "blueprint")
    assert builtin.provenance["horizon_from"] == "common period"
    assert snapshots <= MAX_SNAPSHOTS


def test_each_builtin_mover_goes_round_in_a_whole_number_of_steps_so_the_last_snapshot_leads_into_the_first(builtin):
    for m in builtin.movers:
        steps = m.period_s / builtin.dt_s
        assert steps == pytest.approx(round(steps), abs=0.01), m.name
        x0, y0, yaw0 = m.position_at(0.0)
        x1, y1, yaw1 = m.position_at(builtin.horizon_s)
        assert math.dist((x0, y0), (x1, y1)) < 0.02 and yaw0 == pytest.approx(yaw1), m.name


def test_no_two_builtin_movers_overlap_in_any_snapshot(builtin):
    from shapely.geometry import Polygon

    for k in range(builtin.snapshots):
        boxes = [Polygon(b.corners()) for b in builtin.boxes_at(k)]
        for i, a in enumerate(boxes):
            assert not any(a.intersects(b) for b in boxes[i + 1 :]), (builtin.name, k, i)


def test_each_builtin_snapshot_is_the_blueprint_plus_the_movers_and_only_movers_change(builtin):
    n = len(builtin.base.objects)
    for k in (0, builtin.snapshots // 2, builtin.snapshots - 1):
        spec = builtin.spec_at(k)
        assert spec.objects[:n] == builtin.base.objects and spec.prisms == builtin.base.prisms
        assert [b.name for b in spec.objects[n:]] == [m.name for m in builtin.movers]
    changes = builtin.changed_between(0, 1)
    assert {c.name for c in changes} == {m.name for m in builtin.movers}  # every built-in mover moves every step
    assert all(c.before != c.after and c.before.name == c.after.name for c in changes)


def test_the_moving_twins_digest_is_the_same_on_every_read(builtin):
    again = load_moving_scene(builtin.scene)
    assert again.digest() == builtin.digest()
    assert again.canonical_json() == builtin.canonical_json()


def test_dallas_vehicles_start_where_the_dynamic_twin_parks_them():
    moving = load_moving_scene("dallas-q3")
    parked = {b.name: b for b in load_scene_spec("dallas-q3", "dynamic").objects if b.kind in ("car", "bus")}
    assert {m.name for m in moving.movers} == set(parked)
    for box in moving.boxes_at(0):
        p = parked[box.name]
        assert math.dist((box.x_m, box.y_m), (p.x_m, p.y_m)) < 0.05, box.name
        assert box.yaw_deg == pytest.approx(p.yaw_deg, abs=0.01), box.name  # waypoints are rounded to 1 cm
        assert (box.width_m, box.length_m, box.height_m) == (p.width_m, p.length_m, p.height_m)
        assert (box.material, box.mesh) == (p.material, p.mesh)


def test_dallas_moving_twin_is_its_q3_and_other_quadrants_and_variants_say_where_it_is():
    doc = read_city_file(city_file("dallas"))
    assert city_moving_scene(doc, "q3").name == "dallas-q3/moving"
    with pytest.raises(UnknownNameError, match="the moving twin of dallas is dallas-q3/moving"):
        city_moving_scene(doc, "q2")
    with pytest.raises(SceneFileError, match="series of scenes"):
        city_spec(doc, "q3", "moving")
    assert build_targets("dallas", "moving") == [("dallas-q3", "moving")]  # the city's [moving] quadrant
