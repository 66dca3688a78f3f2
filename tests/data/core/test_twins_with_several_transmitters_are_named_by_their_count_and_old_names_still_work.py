"""A twin with several transmitters is named ``<place>-<N>tx`` (``sionna-munich-10tx``, ``dallas-3tx-q3``), one
separator throughout; the old names (``sionna:munich_cells``, ``sionna-munich_cells``, ``dallas-cells``,
``dallas-cells-q3``) still work wherever a scene or dataset is named, say once that they are old names, and data
stored under an old name still loads, by either name."""

import numpy as np
import pytest

import dtradar_data
from dtradar_data.core import renamed
from dtradar_data.core.errors import SceneFileError
from dtradar_data.core.ids import DatasetId
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.scenes import available_scenes, build_targets, load_scene_spec
from dtradar_data.scenes.names import check_user_scene_name
from dtradar_data.store import writing
from dtradar_data.store.catalog import as_id


@pytest.fixture(autouse=True)
def fresh_notes(monkeypatch):
    monkeypatch.setattr(renamed, "_said", set())  # each test sees the first use of an old name


def test_the_builtin_twins_with_several_transmitters_say_how_many():
    scenes = available_scenes()
    assert "sionna-munich-10tx" in scenes and "dallas-3tx-q3" in scenes
    assert not [s for s in scenes if "cells" in s]
    assert len(load_scene_spec("sionna:munich-10tx", "blueprint").transmitters) == 10
    assert len(load_scene_spec("dallas-3tx-q3", "blueprint").transmitters) == 3


@pytest.mark.parametrize(
    "old, new",
    [
        ("sionna:munich_cells", "sionna:munich-10tx"),
        ("dallas-cells", "dallas-3tx"),
        ("dallas-cells-q3", "dallas-3tx-q3"),
    ],
)
def test_an_old_scene_name_builds_the_renamed_twin_and_says_so_once(old, new, capsys):
    assert build_targets(old) == build_targets(new)
    assert build_targets(old, "blueprint") == build_targets(new, "blueprint")
    err = capsys.readouterr().err
    assert err.count(f"{old!r} is the old name of {new!r}") == 1


def test_an_old_dataset_name_reads_as_the_new_one_in_an_empty_store(root, capsys):
    assert as_id("dallas-cells-q3/dynamic@v0") == DatasetId("dallas-3tx-q3", "dynamic", "v0")
    assert as_id("sionna-munich_cells/blueprint").scene == "sionna-munich-10tx"
    assert "old name of 'sionna-munich-10tx'" in capsys.readouterr().err


def test_data_stored_under_an_old_name_loads_by_either_name(root, capsys):
    ds = synthetic_dataset(8, 6, np.zeros((6, 8), bool), name="dallas-cells-q3/blueprint")
    meta = {**ds.meta, "scene_spec": {"title": "Dallas Q3", "licence": "ODbL-1.0"}, "rt": {"max_depth": 5}}
    version = "0123456789abcdef"
    writing.write_version(DatasetId("dallas-cells-q3", "blueprint"), version, ds.table, meta)  # as stored before
    old = dtradar_data.load("dallas-cells-q3/blueprint")
    assert old.version == version and "stored under the old name" in capsys.readouterr().err
    assert dtradar_data.load("dallas-3tx-q3/blueprint").path == old.path


def test_a_users_scene_may_not_take_an_old_name(tmp_path):
    with pytest.raises(SceneFileError, match="old name of the built-in 'dallas-3tx'"):
        check_user_scene_name("dallas-cells", tmp_path / "mine.toml")
