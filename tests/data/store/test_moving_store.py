"""Moving twins in the store (no ray tracer: synthetic moving twins): their own schemas frozen by golden files,
stored and loaded by name with every snapshot, their rows checked, static datasets' versions untouched."""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pyarrow as pa
import pytest

import dtradar_data
from dtradar_data.core import schema
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.core.ids import DatasetId, parse_id
from dtradar_data.pipeline.synthetic import synthetic_moving_dataset
from dtradar_data.store import listing, writing
from dtradar_data.store.card import render_card

GOLDEN = resources.files("dtradar_data.core") / "golden"
V0 = "0123456789abcdef"
NAME = "synth/moving"


@pytest.mark.parametrize(
    "kind, current", [("moving_cells", schema.MOVING_CELL_SCHEMA), ("moving_paths", schema.MOVING_PATH_SCHEMA)]
)
def test_the_moving_schemas_equal_the_golden_files_of_their_version(kind, current):
    golden = GOLDEN / f"{kind}_v{schema.MOVING_SCHEMA_VERSION}.json"
    assert golden.is_file(), f"a moving schema change needs MOVING_SCHEMA_VERSION bumped and a new {kind}_v{{N}}.json"
    assert schema.schema_to_json(current) == golden.read_text(), (
        f"the {kind} schema changed without bumping MOVING_SCHEMA_VERSION: bump it and add a golden file"
    )


def test_a_moving_schema_is_the_static_one_plus_t_and_mover():
    assert schema.MOVING_CELL_SCHEMA.names == [*schema.CELL_COLUMNS, "t", "mover"]
    assert schema.MOVING_PATH_SCHEMA.names == [*schema.PATH_COLUMNS, "t"]
    assert schema.MOVING_CELL_SCHEMA.field("t").type == pa.int32()
    assert schema.MOVING_CELL_SCHEMA.field("mover").type == pa.bool_()
    assert schema.SCHEMA_VERSION == 1, "static datasets keep their versions: moving twins are versioned on their own"
    meta = schema.MOVING_CELL_SCHEMA.metadata
    assert meta[b"dtradar.static_schema_version"] == str(schema.SCHEMA_VERSION).encode()


def test_moving_is_a_dataset_variant_but_not_a_static_one():
    from dtradar_data.core.ids import VARIANTS

    assert parse_id("cubicle/moving@v0") == DatasetId("cubicle", "moving", "v0")
    assert VARIANTS == ("blueprint", "dynamic")


def _moving(**meta):
    ds = synthetic_moving_dataset(8, 6, name=NAME)
    return ds.table, {**ds.meta, "scene_spec": {"title": "Synthetic"}, **meta}


def test_a_moving_twin_is_stored_and_loads_by_name_with_every_snapshot(root):
    cells, meta = _moving()
    shuffled = cells.take(np.random.default_rng(0).permutation(cells.num_rows))
    path = writing.write_version(NAME, V0, shuffled, meta)
    ds = dtradar_data.load(NAME)
    assert ds.version == V0 and ds.path == path
    assert ds.table.schema.names == schema.MOVING_CELL_SCHEMA.names
    assert ds.table.equals(cells.select(schema.MOVING_CELL_SCHEMA.names).cast(ds.table.schema)), "sorted (t, iy, ix)"
    assert ds.snapshots == meta["moving"]["snapshots"] and ds.snapshot(1).table.num_rows == 48
    stored = json.loads((path / "meta.json").read_text())
    assert stored["moving"] == meta["moving"] and stored["moving_schema_version"] == schema.MOVING_SCHEMA_VERSION
    assert listing.verify(NAME) == {V0: []}
    entry = next(e for e in listing.list_datasets() if e.name == NAME)
    assert entry.versions[0].num_rows == cells.num_rows
    card = (path / "README.md").read_text()
    assert "### Moving twin" in card and "× 6 × " in card and "`mover`" in card


def test_a_moving_table_missing_a_snapshot_or_with_a_mover_on_a_free_cell_is_refused(root):
    cells, meta = _moving()
    with pytest.raises(writing.InvalidTableError, match="in each of"):
        writing.write_version(NAME, V0, cells.slice(0, cells.num_rows - 48), meta)
    mover = cells.column("mover").to_numpy(zero_copy_only=False).copy()
    free = ~cells.column("blocked").to_numpy(zero_copy_only=False)
    mover[np.flatnonzero(free)[0]] = True
    bad = cells.set_column(cells.schema.get_field_index("mover"), "mover", pa.array(mover))
    with pytest.raises(writing.InvalidTableError, match="mover true and blocked false"):
        writing.write_version(NAME, V0, bad, meta)
    with pytest.raises(SchemaMismatchError, match="moving-cells v1"):
        writing.write_version(NAME, V0, cells.drop_columns(["mover"]), meta)


def test_the_card_of_a_moving_twin_lists_its_snapshots(root):
    cells, meta = _moving()
    record = {
        "movers": [{"name": "walker-0", "kind": "person", "speed_mps": 1.0, "mode": "loop", "waypoints": [[0, 0]] * 2}],
        "per_snapshot": [
            {"t": 0, "mode": "full", "retraced_cells": 40, "free_cells": 40, "movers_moved": [], "seconds": 2.0},
            {"t": 1, "mode": "differential", "retraced_cells": 7, "free_cells": 40, "movers_moved": ["walker-0"]},
        ],
        "retraced_cells_mean": 7.0,
        "free_cells_mean": 40.0,
    }
    text = render_card(
        {**meta, "name": NAME, "scene": "synth", "variant": "moving", "version": V0, "moving_build": record},
        tag="v0",
        history=[],
    )
    assert "| 1 | differential | 7 | 40 | walker-0 |" in text
    assert "On average 7 of 40 free cells were re-traced" in text
