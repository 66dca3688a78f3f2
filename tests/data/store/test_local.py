"""The local Parquet store: atomic versioned writes, checked reads, typed errors that say how to fix."""

import json
import os

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import dtradar_data
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    RevisionNotFoundError,
    SchemaMismatchError,
    UnknownNameError,
)
from dtradar_data.core.schema import CELL_SCHEMA, PATH_SCHEMA, RADIO_COLUMNS
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import local as store
from dtradar_data.store import writing

V0, V1 = "0123456789abcdef", "fedcba9876543210"


def blocked_mask(nx=8, ny=6):
    b = np.zeros((ny, nx), bool)
    b[2, 3] = b[4, 0] = True
    return b


def make(name="cubicle/blueprint", nx=8, ny=6, **meta):
    ds = synthetic_dataset(nx, ny, blocked_mask(nx, ny), name=name)
    full = {**ds.meta, "scene_spec": {"title": "Cubicle", "licence": "CC-BY-4.0"}, "rt": {"max_depth": 5}, **meta}
    return ds.table, full


def paths_table(cells: pa.Table) -> pa.Table:
    free = cells.filter(pa.compute.invert(cells.column("blocked")))
    n = free.num_rows
    f32 = lambda v: pa.array(np.full(n, v, np.float32))  # noqa: E731
    return pa.Table.from_pydict(
        {
            "ix": free.column("ix"),
            "iy": free.column("iy"),
            "path": pa.array(np.zeros(n, np.int16)),
            "a_re": free.column("a_re"),
            "a_im": free.column("a_im"),
            "power_db": free.column("path_gain_db"),
            "tau_s": free.column("tau_s"),
            "aod_zen_rad": f32(1.0),
            "aod_az_rad": f32(0.5),
            "aoa_zen_rad": f32(2.0),
            "aoa_az_rad": f32(-0.5),
            "depth": pa.array(np.zeros(n, np.int8)),
            "interactions": pa.array([""] * n),
        },
        schema=PATH_SCHEMA,
    )


def test_write_then_load_roundtrips_the_table_the_grid_and_the_mask(root):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    assert path == root / "datasets" / "cubicle" / "blueprint" / V0
    assert {p.name for p in path.iterdir()} == {"cells.parquet", "meta.json", "README.md"}
    ds = dtradar_data.load("cubicle/blueprint")
    assert ds.version == V0 and ds.meta["tag"] == "v0" and ds.name == "cubicle/blueprint"
    assert ds.table.equals(cells)
    assert ds.grid().shape == (6, 8, len(RADIO_COLUMNS)) and ds.grid().dtype == np.float32
    np.testing.assert_array_equal(ds.blocked, blocked_mask())
    assert np.isnan(ds.grid()[2, 3]).all() and not np.isnan(ds.grid()[0, 0]).any()
    assert ds.paths_table is None


def test_the_parquet_file_carries_the_explicit_schema_zstd_and_the_metadata(root):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    pf = pq.ParquetFile(path / "cells.parquet")
    assert pf.schema_arrow.remove_metadata().equals(CELL_SCHEMA.remove_metadata())
    assert pf.metadata.row_group(0).column(0).compression == "ZSTD"
    embedded = json.loads(pf.schema_arrow.metadata[b"dtradar.meta"])
    assert embedded["version"] == V0 and embedded["name"] == "cubicle/blueprint" and "files" not in embedded
    stored = json.loads((path / "meta.json").read_text())
    assert stored["files"]["cells.parquet"]["sha256"] == store.sha256_file(path / "cells.parquet")
    assert stored["stats"]["num_cells"] == 48 and stored["stats"]["num_free"] == 46


def test_rows_in_any_order_are_stored_row_major(root):
    cells, meta = make()
    shuffled = cells.take(np.random.default_rng(0).permutation(cells.num_rows))
    writing.write_version("cubicle/blueprint", V0, shuffled, meta)
    assert dtradar_data.load("cubicle/blueprint").table.equals(cells)


def test_the_per_path_table_and_extra_files_are_stored_and_loaded_on_request(root, tmp_path):
    cells, meta = make()
    png = tmp_path / "cov.png"
    png.write_bytes(b"\x89PNG fake")
    path = writing.write_version(
        "cubicle/blueprint", V0, cells, meta, paths=paths_table(cells), extra_files={"coverage.png": png}
    )
    assert (path / "coverage.png").read_bytes() == png.read_bytes()
    ds = store.load("cubicle/blueprint", paths=True)
    assert ds.paths_table.num_rows == 46
    card = (path / "README.md").read_text()
    assert "![Sionna's radio map" in card and "cells.png" not in card  # no table picture stored: none shown


def test_writing_an_existing_version_reuses_it_and_never_rewrites(root):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    before = (path / "cells.parquet").stat().st_mtime_ns, (path / "meta.json").read_text()
    again = writing.write_version("cubicle/blueprint", V0, cells, {**meta, "rt": {"max_depth": 99}})
    assert again == path and ((path / "cells.parquet").stat().st_mtime_ns, (path / "meta.json").read_text()) == before
    assert json.loads((path.parent / "refs.json").read_text())["tags"] == {"v0": V0}


def test_a_schema_mismatch_fails_the_write_and_leaves_nothing_behind(root):
    cells, meta = make()
    bad = cells.set_column(cells.schema.get_field_index("tau_s"), "tau_s", cells.column("tau_s").cast(pa.float64()))
    with pytest.raises(SchemaMismatchError, match="'tau_s' has type double, expected float"):
        writing.write_version("cubicle/blueprint", V0, bad, meta)
    with pytest.raises(SchemaMismatchError, match="missing column 'los'"):
        writing.write_version("cubicle/blueprint", V0, cells.drop_columns(["los"]), meta)
    assert not store.version_exists("cubicle/blueprint", V0)
    assert not (root / "work").exists() or list((root / "work").iterdir()) == []
    assert not (root / "datasets" / "cubicle" / "blueprint" / V0).exists()


def test_a_failure_in_the_middle_of_a_write_leaves_no_version_and_no_temp_dir(root, monkeypatch):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    refs_before = (root / "datasets/cubicle/blueprint/refs.json").read_text()

    def boom(*args, **kwargs):
        raise OSError("disk full (injected)")

    monkeypatch.setattr(writing, "_write_parquet", boom)
    with pytest.raises(OSError, match="injected"):
        writing.write_version("cubicle/blueprint", V1, cells, meta)
    assert not (root / "datasets/cubicle/blueprint" / V1).exists()
    assert list((root / "work").iterdir()) == []
    assert (root / "datasets/cubicle/blueprint/refs.json").read_text() == refs_before
    assert store.load("cubicle/blueprint").version == V0


def test_a_failure_while_renaming_into_place_leaves_refs_and_versions_untouched(root, monkeypatch):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)

    def no_rename(src, dst):
        raise OSError("rename failed (injected)")

    monkeypatch.setattr(writing.os, "rename", no_rename)
    with pytest.raises(OSError, match="injected"):
        writing.write_version("cubicle/blueprint", V1, cells, meta)
    assert sorted(
        p.name for p in (root / "datasets/cubicle/blueprint").iterdir() if not p.name.startswith(".")
    ) == sorted(["refs.json", V0])
    assert list((root / "work").iterdir()) == []


def test_rows_that_do_not_form_the_grid_are_rejected(root):
    cells, meta = make()
    with pytest.raises(writing.InvalidTableError, match="not the 8x6 grid"):
        writing.write_version("cubicle/blueprint", V0, cells.slice(0, 47), meta)


def test_nulls_in_a_non_null_column_are_a_schema_mismatch(root):
    cells, meta = make()
    i = cells.schema.get_field_index("num_paths")
    nulled = cells.set_column(i, pa.field("num_paths", pa.int16()), pa.array([None] * 48, pa.int16()))
    with pytest.raises(SchemaMismatchError, match="'num_paths' has 48 nulls"):
        writing.write_version("cubicle/blueprint", V0, nulled, meta)


def test_unknown_name_on_load_suggests_the_closest(root):
    with pytest.raises(UnknownNameError, match="did you mean 'cubicle/blueprint'"):
        dtradar_data.load("cubical/blueprint")


def test_a_known_but_unbuilt_dataset_says_how_to_build_it(root):
    with pytest.raises(DatasetNotFoundError, match="make dataset SCENE=meeting"):
        dtradar_data.load("meeting/dynamic")


def test_a_missing_revision_lists_the_existing_versions(root):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    with pytest.raises(RevisionNotFoundError) as err:
        store.load("cubicle/blueprint@v7")
    assert f"v0 = {V0}" in str(err.value)
    with pytest.raises(RevisionNotFoundError, match="has no version 'abcdef1'"):
        store.load("cubicle/blueprint", revision="abcdef1")


def corrupt(path, how):
    data = bytearray(path.read_bytes())
    if how == "truncate":
        data = data[: len(data) // 2]
    else:  # flip one byte inside the first data page (after the 4-byte magic)
        data[len(data) // 3] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["truncate", "flip"])
def test_a_corrupt_parquet_file_is_reported_with_its_name_and_how_to_fix(root, how):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    corrupt(path / "cells.parquet", how)
    with pytest.raises(CorruptDatasetError) as err:
        store.load("cubicle/blueprint")
    assert "cells.parquet" in str(err.value) and "re-pull" in str(err.value)


@pytest.mark.parametrize("how", ["truncate", "flip"])
def test_parquet_level_corruption_is_caught_even_without_the_hash_check(root, how):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    corrupt(path / "cells.parquet", how)
    with pytest.raises(CorruptDatasetError, match="cells.parquet"):
        store.load("cubicle/blueprint", verify=False)


def test_a_stored_file_with_another_schema_is_a_schema_mismatch_naming_the_differences(root):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    wrong = cells.drop_columns(["delay_spread_s"]).append_column("extra_col", pa.array(np.zeros(48)))
    pq.write_table(wrong, path / "cells.parquet")
    with pytest.raises(SchemaMismatchError) as err:
        store.load("cubicle/blueprint", verify=False)
    msg = str(err.value)
    assert "cells.parquet" in msg and "missing column 'delay_spread_s'" in msg and "extra column 'extra_col'" in msg


def test_list_datasets_shows_builtin_scenes_and_stored_versions(root):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    rows = {r.name: r for r in dtradar_data.list_datasets()}
    assert {"cubicle/blueprint", "cubicle/dynamic", "meeting/blueprint", "meeting/dynamic"} <= set(rows)
    assert rows["cubicle/blueprint"].built and rows["cubicle/blueprint"].latest == V0
    assert rows["cubicle/blueprint"].versions[0].tag == "v0" and rows["cubicle/blueprint"].versions[0].num_rows == 48
    assert not rows["meeting/dynamic"].built


def test_a_refs_file_written_by_hand_badly_is_a_typed_error(root):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    (root / "datasets/cubicle/blueprint/refs.json").write_text("{not json")
    with pytest.raises(CorruptDatasetError, match="refs.json"):
        store.load("cubicle/blueprint")


def test_refs_is_replaced_atomically_without_leftover_temp_files(root):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    writing.write_version("cubicle/blueprint", V1, cells, meta)
    ddir = root / "datasets/cubicle/blueprint"
    assert sorted(os.listdir(ddir)) == sorted([".lock", "refs.json", V0, V1])


@pytest.mark.parametrize("verify", [True, False])
def test_a_deleted_cells_file_is_a_corrupt_dataset_naming_it_and_how_to_get_the_version_back(root, verify):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    (path / "cells.parquet").unlink()
    with pytest.raises(CorruptDatasetError) as err:
        dtradar_data.load("cubicle/blueprint", verify=verify)
    text = str(err.value)
    assert f"{path / 'cells.parquet'} is missing: cubicle/blueprint@{V0} is damaged" in text
    assert "`python -m dtradar_data verify cubicle/blueprint`" in text and f"`rm -r {path}`" in text
    assert "`make dataset SCENE=cubicle`" in text and "`python -m dtradar_data pull cubicle/blueprint@v0`" in text


def test_a_deleted_paths_file_that_meta_json_lists_is_damage_not_a_build_without_paths(root):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta, paths=paths_table(cells))
    (path / "paths.parquet").unlink()
    assert dtradar_data.load("cubicle/blueprint").paths_table is None  # the cells alone still load
    with pytest.raises(CorruptDatasetError, match=r"paths\.parquet is missing: .* is damaged(?s:.*)rm -r"):
        dtradar_data.load("cubicle/blueprint", paths=True)
    writing.write_version("cubicle/blueprint", V1, cells, {**meta, "built": "without paths"})
    with pytest.raises(DatasetNotFoundError, match="built without the per-path table"):
        dtradar_data.load("cubicle/blueprint@v1", paths=True)


@pytest.mark.parametrize("revision", [None, "v0", V0])
def test_a_deleted_meta_json_is_a_corrupt_dataset_not_one_never_built(root, revision):
    cells, meta = make()
    path = writing.write_version("cubicle/blueprint", V0, cells, meta)
    (path / "meta.json").unlink()
    with pytest.raises(CorruptDatasetError, match=r"meta\.json is missing(?s:.*)how to fix: .*verify.*rm -r"):
        dtradar_data.load("cubicle/blueprint", revision)


def test_the_newest_version_damaged_is_refused_rather_than_an_older_one_loaded_in_its_place(root):
    cells, meta = make()
    writing.write_version("cubicle/blueprint", V0, cells, meta)
    newest = writing.write_version("cubicle/blueprint", V1, cells, {**meta, "rt": {"max_depth": 9}})
    (newest / "meta.json").unlink()
    with pytest.raises(CorruptDatasetError, match=f"{V1}/meta.json is missing(?s:.*)pull cubicle/blueprint@v1"):
        dtradar_data.load("cubicle/blueprint")
    assert dtradar_data.load("cubicle/blueprint@v0").version == V0
