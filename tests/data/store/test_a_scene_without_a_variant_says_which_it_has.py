"""A built-in scene's variant that its scene file does not make (``dallas-q1/dynamic``: Dallas has one dynamic
quadrant, Q3; Sionna's bundled scenes have no dynamic twin) is refused plainly, naming the datasets the scene has,
instead of a build command that then refuses. It stays a DatasetNotFoundError, so whatever skips an unbuilt twin
(evaluation, benchmarks) still skips it; a copy in the store is loaded as any other."""

import pytest

import dtradar_data
from dtradar_data import cli
from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import hub
from dtradar_data.store import writing

V0 = "0123456789abcdef"


def test_loading_a_twin_the_scene_lacks_names_the_ones_it_has(root):
    with pytest.raises(DatasetNotFoundError) as err:
        dtradar_data.load("dallas-q1/dynamic")
    assert err.value.message == (
        "dallas-q1 has no dynamic twin, so dallas-q1/dynamic cannot be built or pulled; "
        "its datasets are dallas-q1/blueprint"
    )
    assert err.value.hint.startswith("use dallas-q1/blueprint, or another scene's dynamic twin: ")
    assert "dallas-q3/dynamic" in err.value.hint and "make dataset" not in str(err.value)


@pytest.mark.parametrize(
    "name, has",
    [
        ("sionna-munich/dynamic", "sionna-munich/blueprint"),
        ("dallas-q1/moving", "dallas-q1/blueprint"),
        ("houston-q4/dynamic", "houston-q4/blueprint"),
    ],
)
def test_no_missing_twin_is_offered_a_build(root, name, has):
    with pytest.raises(DatasetNotFoundError) as err:
        dtradar_data.load(name)
    scene, variant = name.split("/")
    assert f"{scene} has no {variant} twin" in err.value.message and f"its datasets are {has}" in err.value.message
    assert "make dataset" not in str(err.value) and "build --scene" not in str(err.value)


def test_a_twin_the_scene_has_still_says_how_to_build_it(root):
    with pytest.raises(DatasetNotFoundError, match="make dataset SCENE=dallas-q3 VARIANT=moving"):
        dtradar_data.load("dallas-q3/moving")


def test_a_stored_copy_of_such_a_twin_is_loaded(root):
    ds = synthetic_dataset(5, 3, name="dallas-q1/dynamic")
    writing.write_version("dallas-q1/dynamic", V0, ds.table, {**ds.meta, "rt": {"max_depth": 5}})
    assert dtradar_data.load("dallas-q1/dynamic").version == V0


def test_the_cli_says_so_for_info_and_pull(root, capsys, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    for command in ("info", "pull"):
        assert cli.main([command, "dallas-q1/dynamic"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: dallas-q1 has no dynamic twin") and "how to fix: use dallas-q1/blueprint" in err
        assert "make dataset" not in err
    with pytest.raises(DatasetNotFoundError, match="has no dynamic twin"):
        hub.pull("dallas-q1/dynamic@v0")
    assert not (root / "datasets" / "dallas-q1").exists()
