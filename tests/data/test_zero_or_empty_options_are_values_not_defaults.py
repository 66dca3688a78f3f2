"""An option given as 0 or "" is a value, checked like any other, never taken as "not given": `--cell-m 0` on a city
quadrant used to build at the city file's cell size, `--osm ""` from the city file's footprints (a truthiness test,
``cell_m or default``). Only an option left out (None) falls back to the scene's own value."""

import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.scenes import load_scene_spec
from dtradar_data.scenes.city import reader as city_reader
from dtradar_data.scenes.city.document import read_city_file
from dtradar_data.scenes.city.reader import city_file, city_spec, quadrant_grid


@pytest.fixture()
def nothing_expensive(monkeypatch):
    def expensive(*args, **kwargs):
        raise AssertionError("an expensive step ran for an option that should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", expensive)
    monkeypatch.setattr(static_build, "RayTracer", expensive)
    monkeypatch.setattr(city_reader, "city_footprints", expensive)


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--scene", "dallas-q3", "--cell-m", "0"], "--cell-m"),
        (["--scene", "houston", "--cell-m", "0"], "--cell-m"),
        (["--scene", "sionna:munich", "--cell-m", "0"], "--cell-m"),
        (["--scene", "dallas-q3", "--osm", ""], "--osm"),
        (["--scene", "dallas-q3", "--osm", "  "], "--osm"),
    ],
)
def test_a_zero_or_empty_option_is_refused_not_replaced_by_the_default(root, nothing_expensive, capsys, argv, flag):
    assert cli.main(["build", "--no-progress", *argv]) == 2
    line = capsys.readouterr().err.splitlines()[0]
    assert line.startswith("error: ") and flag in line
    assert not root.exists()


@pytest.mark.parametrize("cell_m", [0, 0.0, -0.0])
def test_the_city_reader_refuses_a_zero_cell_size_given_as_an_option(nothing_expensive, cell_m):
    with pytest.raises(InvalidSettingError, match="--cell-m"):
        city_spec(read_city_file(city_file("dallas")), "q3", "blueprint", cell_m=cell_m)
    with pytest.raises(InvalidSettingError, match="--cell-m"):
        quadrant_grid("q3", 200.0, 200.0, cell_m, option=True)
    with pytest.raises(InvalidSettingError, match="--cell-m"):
        load_scene_spec("dallas-q3", "blueprint", cell_m=cell_m)


def test_an_empty_footprint_source_is_refused_not_replaced_by_the_city_files(nothing_expensive):
    with pytest.raises(InvalidSettingError, match="--osm"):
        load_scene_spec("dallas-q3", "blueprint", footprints="")


def test_an_option_left_out_keeps_the_scene_files_value():
    doc = read_city_file(city_file("dallas"))
    spec = load_scene_spec("dallas-q3", "blueprint")
    assert spec.grid.cell_m == doc.grid.cell_m
    assert load_scene_spec("dallas-q3", "blueprint", cell_m=8.0).grid.cell_m == 8.0
