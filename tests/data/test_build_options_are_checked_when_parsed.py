"""Build options that replace part of a scene (--tx, --grid, --cell-m) are checked as values when they are parsed:
a NaN, an infinity, a cell size of zero or below, or a grid far too large for memory is an InvalidSettingError that
names the flag (exit status 2 from the CLI), before any scene mesh, footprint or ray is touched and with nothing
written to the data root. Every grid, whatever made it, is bounded the same way (a scene file's names the file)."""

import math

import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidSettingError, SceneFileError
from dtradar_data.core.grid import MAX_CELLS, Grid
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.scenes import load_scene_spec, xml_scene
from dtradar_data.scenes.city import reader as city_reader


@pytest.fixture()
def nothing_expensive(monkeypatch):
    """Tracing, reading an XML scene's meshes or a city's footprints fails the test: the checks come first."""

    def expensive(*args, **kwargs):
        raise AssertionError("an expensive step ran for an option that should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", expensive)
    monkeypatch.setattr(static_build, "RayTracer", expensive)
    monkeypatch.setattr(xml_scene, "mesh_scene", expensive)
    monkeypatch.setattr(city_reader, "city_footprints", expensive)


BAD = [
    (["--scene", "sionna:munich", "--tx", "nan", "0", "20"], "--tx"),
    (["--scene", "sionna:munich", "--tx", "0", "inf", "20"], "--tx"),
    (["--scene", "sionna:munich", "--tx", "0", "0", "-inf"], "--tx"),
    (["--scene", "sionna:munich", "--grid", "nan", "0", "5", "10", "10"], "--grid"),
    (["--scene", "sionna:munich", "--grid", "0", "0", "inf", "10", "10"], "--grid"),
    (["--scene", "sionna:munich", "--grid", "0", "0", "0", "10", "10"], "--grid"),
    (["--scene", "sionna:munich", "--grid", "0", "0", "-1", "10", "10"], "--grid"),
    (["--scene", "sionna:munich", "--grid", "0", "0", "1", "0", "10"], "--grid"),
    (["--scene", "sionna:munich", "--grid", "0", "0", "1", "100000", "100000"], "--grid"),
    (["--scene", "sionna:munich", "--cell-m", "nan"], "--cell-m"),
    (["--scene", "sionna:munich", "--cell-m", "-2"], "--cell-m"),
    (["--scene", "sionna:munich", "--cell-m", "0.001"], "--cell-m"),
    (["--scene", "dallas-q3", "--cell-m", "inf"], "--cell-m"),
    (["--scene", "dallas-q3", "--cell-m", "-5"], "--cell-m"),
    (["--scene", "dallas-q3", "--cell-m", "0.01"], "--cell-m"),
    (["--scene", "cubicle", "--retrace-radius-m", "nan", "--differential"], "--retrace-radius-m"),
]


@pytest.mark.parametrize("argv, flag", BAD, ids=[" ".join(a[1:]) for a, _ in BAD])
def test_a_bad_option_value_exits_2_naming_its_flag_before_anything_runs(root, nothing_expensive, capsys, argv, flag):
    assert cli.main(["build", "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and flag in err.splitlines()[0] and "how to fix:" in err, err
    assert "Traceback" not in err and "unexpected" not in err
    assert not root.exists()


def test_a_grid_too_large_for_memory_says_how_many_cells_and_how_much_memory(root, nothing_expensive, capsys):
    assert cli.main(["build", "--scene", "sionna:munich", "--grid", "0", "0", "1", "100000", "100000"]) == 2
    line = capsys.readouterr().err.splitlines()[0]
    assert "10,000,000,000 cells" in line and f"{MAX_CELLS:,}" in line and "GiB" in line


@pytest.mark.parametrize(
    "options, flag",
    [
        ({"tx": (math.nan, 0, 20)}, "--tx"),
        ({"grid": (0, 0, 0.0, 10, 10)}, "--grid"),
        ({"grid": (0, 0, 1, 3000, 3000)}, "--grid"),
        ({"cell_m": 0.0}, "--cell-m"),
        ({"cell_m": math.inf}, "--cell-m"),
    ],
)
def test_the_python_api_checks_the_options_too(nothing_expensive, options, flag):
    with pytest.raises(InvalidSettingError, match=flag):
        load_scene_spec("sionna:munich", "blueprint", **options)


@pytest.mark.parametrize(
    "values",
    [
        (0, 0, 0.0, 2, 2),
        (0, 0, -1.0, 2, 2),
        (math.nan, 0, 1.0, 2, 2),
        (0, math.inf, 1.0, 2, 2),
        (0, 0, 1.0, 0, 2),
        (0, 0, 1.0, 2, 2.5),
        (0, 0, 1.0, MAX_CELLS, 2),
    ],
)
def test_a_grid_cannot_be_made_with_impossible_values(values):
    with pytest.raises(InvalidSettingError, match="invalid receiver grid"):
        Grid(*values)


def test_a_grid_of_at_most_max_cells_is_fine():
    assert Grid(0.5, 0.5, 1.0, 2000, 2000).shape == (2000, 2000)


def test_a_scene_files_grid_too_large_for_memory_is_refused_when_read_naming_the_file(tmp_path, tiny_room):
    big = (
        tiny_room.replace("width_m = 2.0", "width_m = 5000.0")
        .replace("length_m = 1.5", "length_m = 5000.0")
        .replace("cell_m = 0.5\nnx = 4\nny = 3", "cell_m = 1.0\nnx = 5000\nny = 5000")
    )
    path = tmp_path / "big.toml"
    path.write_text(big)
    with pytest.raises(SceneFileError, match=r"big\.toml: \[grid\]: 5000 x 5000 = 25,000,000 cells"):
        load_scene_spec(path, "blueprint")


@pytest.mark.parametrize(
    "kw, flag",
    [
        (dict(retrace_radius_m=float("nan"), differential=True), "--retrace-radius-m"),
        (dict(tx=(1.0, float("nan"), 2.0)), "--tx"),
        (dict(grid=(0.0, 0.0, float("inf"), 4, 4)), "--grid"),
        (dict(cell_m=0.0), "--cell-m"),
        (dict(ray_address=""), "--ray-address"),
        (dict(workers=-1), "--workers"),
    ],
)
def test_a_build_config_made_in_python_checks_the_same_values_as_the_command_line(kw, flag):
    with pytest.raises(InvalidSettingError) as e:
        BuildConfig(scene="cubicle", **kw)
    assert flag in str(e.value) and "how to fix" in str(e.value)
