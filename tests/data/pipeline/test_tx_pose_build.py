"""Building an antenna-pose-error twin (``--tx-pose-error``): both variants under ``<scene>-txpose`` with one pose,
never a version of the original twin (the builds need Sionna; a 2 x 1.5 m room traces in about a second)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

#: What the shared tiny room gets here: a ceiling access point looking straight down, and a dynamic twin.
DYNAMIC = """
[dynamic]
description = "a second box"
[[dynamic.add]]
name = "box_02"
kind = "box"
material = "wood"
x_m = 1.75
y_m = 1.25
width_m = 0.4
length_m = 0.4
height_m = 0.8
"""


@pytest.fixture
def config(tmp_path, tiny_room):
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    path = tmp_path / "pose-room.toml"
    room = tiny_room.replace('name = "tiny-room"', 'name = "pose-room"')
    room = room.replace(
        "position_m = [1.0, 0.75, 2.4]\n", "position_m = [1.0, 0.75, 2.4]\nlook_at_m = [1.0, 0.75, 0.0]\n"
    )
    path.write_text(room + DYNAMIC)
    return BuildConfig(
        scene=str(path),
        rt=RTSettings(max_depth=1, samples_per_src=2_000, device="cpu"),
        coverage_map=False,
        progress=False,
    )


@pytest.mark.sionna
def test_the_pose_twin_is_stored_under_its_own_name_with_one_pose_for_both_variants(root, config):
    import dtradar_data
    from dtradar_data.core.errors import DatasetNotFoundError, UnknownNameError
    from dtradar_data.pipeline.builder import build

    blueprint, dynamic = build(replace(config, tx_pose_error=(0.5, 5.0)))
    assert (blueprint.name, dynamic.name) == ("pose-room-txpose/blueprint", "pose-room-txpose/dynamic")
    metas = [json.loads((d.path / "meta.json").read_text()) for d in (blueprint, dynamic)]
    assert metas[0]["transmitter"] == metas[1]["transmitter"], "the same access point in the same room"
    tx = metas[0]["transmitter"]
    assert math.dist(tx["position_m"], (1.0, 0.75, 2.4)) == pytest.approx(0.5, abs=1e-5)
    assert metas[0]["tx_pose_error"]["angle_deg"] == 5.0 and "city" not in metas[0]
    assert "Antenna-pose-error twin" in (blueprint.path / "README.md").read_text()
    assert dtradar_data.load("pose-room-txpose/blueprint").version == blueprint.version
    with pytest.raises((DatasetNotFoundError, UnknownNameError)):  # the original twin was not built
        dtradar_data.load("pose-room/blueprint")

    (plain,) = build(replace(config, variant="blueprint"))
    assert plain.name == "pose-room/blueprint" and plain.version != blueprint.version
    assert dtradar_data.load("pose-room-txpose/blueprint").version == blueprint.version, "untouched by the plain build"
    entries = {e.name: e for e in dtradar_data.list_datasets()}
    assert [v.version for v in entries["pose-room/blueprint"].versions] == [plain.version]
    assert [v.version for v in entries["pose-room-txpose/blueprint"].versions] == [blueprint.version]
    np.testing.assert_array_equal(plain.blocked, blueprint.blocked)
    moved = plain.frame["path_gain_db"].to_numpy() != blueprint.frame["path_gain_db"].to_numpy()
    assert moved[~plain.blocked.ravel()].any(), "moving the transmitter changes the radio features"


@pytest.mark.sionna
def test_the_tracer_orients_the_array_exactly_as_the_pose_twin_says(config):
    from dtradar_data.rt.settings import RTSettings
    from dtradar_data.rt.tracer import RayTracer
    from dtradar_data.scenes import load_scene_spec
    from dtradar_data.scenes.tx_pose import tx_pose_error

    twin = tx_pose_error(load_scene_spec(config.scene, "blueprint"), offset_m=0.5, angle_deg=5.0, seed=1)
    tracer = RayTracer(twin, RTSettings(device="cpu"))
    try:
        got = np.degrees(np.array(tracer.scene.transmitters["tx"].orientation, dtype=float).ravel())
    finally:
        tracer.close()
    np.testing.assert_allclose(got, twin.tx.orientation_deg, atol=1e-4)


def test_a_city_quadrants_pose_twin_builds_both_variants_with_one_pose_and_the_outdoor_settings():
    from dtradar_data.pipeline.config import BuildConfig, scene_config
    from dtradar_data.pipeline.static_build import build_specs
    from dtradar_data.scenes import load_scene_spec

    config = BuildConfig(scene="dallas-q3", tx_pose_error=(0.5, 5.0), tx_pose_seed=3)
    blueprint, dynamic = build_specs(config)
    assert (blueprint.name, dynamic.name) == ("dallas-q3-txpose/blueprint", "dallas-q3-txpose/dynamic")
    assert blueprint.tx == dynamic.tx and blueprint.tx.position_m[2] == 18.0
    plain = load_scene_spec("dallas-q3", "blueprint")
    assert math.dist(plain.tx.position_m, blueprint.tx.position_m) == pytest.approx(0.5, abs=1e-5)
    assert scene_config(config, blueprint).rt == scene_config(config, plain).rt, (
        "the same RT settings as the plain twin"
    )
    assert blueprint.provenance["tx_pose_error"]["seed"] == 3


@pytest.mark.parametrize("bad", [(-0.5, 5.0), (0.5, 90.0), (float("nan"), 5.0)])
def test_a_bad_tx_pose_error_fails_when_the_config_is_made(bad):
    from dtradar_data.core.errors import InvalidSettingError
    from dtradar_data.pipeline.config import BuildConfig

    with pytest.raises(InvalidSettingError, match="--tx-pose-error"):
        BuildConfig(scene="cubicle", tx_pose_error=bad)
