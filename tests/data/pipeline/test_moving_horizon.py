"""``--horizon-s``: a moving twin over another horizon than its scene file's, in whole robot steps, with its own
version; refused where it does not apply or makes no snapshot or too many (no ray tracer needed)."""

import math

import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.inputs import moving_build_inputs
from dtradar_data.pipeline.moving_build import moving_scenes
from dtradar_data.scenes.moving_scene import MAX_SNAPSHOTS
from dtradar_data.store.versions import version_id


def version(config, scene):
    return version_id(moving_build_inputs(scene, scene_config(config, scene.base), libraries={}))


def test_a_horizon_gives_the_twin_that_many_whole_steps_and_its_own_version():
    default = BuildConfig(scene="cubicle", variant="moving")
    (period,) = moving_scenes(default)
    longer = BuildConfig(scene="cubicle", variant="moving", horizon_s=period.horizon_s + 2.4 * period.dt_s)
    (scene,) = moving_scenes(longer)
    assert scene.snapshots == period.snapshots + 2  # 2.4 steps round to 2
    assert scene.provenance["horizon_from"] == "--horizon-s" and scene.provenance["snapshots"] == scene.snapshots
    assert scene.spec_at(scene.snapshots - 1) != scene.spec_at(0), "past the period the movers go on walking"
    assert version(longer, scene) != version(default, period)
    same = BuildConfig(scene="cubicle", variant="moving", horizon_s=period.horizon_s)
    assert version(same, moving_scenes(same)[0]) == version(default, period), "the period given is the default"


def test_a_horizon_outside_one_to_the_most_snapshots_is_refused_naming_what_fits():
    (scene,) = moving_scenes(BuildConfig(scene="cubicle", variant="moving"))
    for horizon in (0.4 * scene.dt_s, (MAX_SNAPSHOTS + 1) * scene.dt_s):
        with pytest.raises(InvalidSettingError, match="--horizon-s") as err:
            moving_scenes(BuildConfig(scene="cubicle", variant="moving", horizon_s=horizon))
        assert f"{MAX_SNAPSHOTS * scene.dt_s:g}" in err.value.hint


@pytest.mark.parametrize("horizon", [0.0, -3.0, math.nan, math.inf])
def test_a_horizon_that_is_not_a_positive_number_is_refused(horizon):
    with pytest.raises(InvalidSettingError, match="--horizon-s"):
        BuildConfig(scene="cubicle", variant="moving", horizon_s=horizon)


def test_a_horizon_without_variant_moving_is_refused_not_ignored():
    with pytest.raises(InvalidSettingError, match="--horizon-s applies to --variant moving only"):
        BuildConfig(scene="cubicle", variant="all", horizon_s=60.0)
