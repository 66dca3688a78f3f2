"""The per-cell and per-path schemas are frozen per SCHEMA_VERSION by golden files."""

import json
from importlib import resources

import pytest

from dtradar_data.core import schema

GOLDEN = resources.files("dtradar_data.core") / "golden"


@pytest.mark.parametrize("kind, current", [("cells", schema.CELL_SCHEMA), ("paths", schema.PATH_SCHEMA)])
def test_the_current_schema_equals_the_golden_file_of_its_version(kind, current):
    golden = GOLDEN / f"{kind}_v{schema.SCHEMA_VERSION}.json"
    assert golden.is_file(), (
        f"no golden file for schema v{schema.SCHEMA_VERSION}: a schema change needs a version "
        f"bump and a new dtradar_data/golden/{kind}_v{{N}}.json"
    )
    assert schema.schema_to_json(current) == golden.read_text(), (
        f"the {kind} schema changed without bumping SCHEMA_VERSION (now {schema.SCHEMA_VERSION}): bump it and add "
        f"a new golden file rather than editing {golden.name}"
    )


def test_golden_files_record_the_version_they_belong_to():
    for path in GOLDEN.iterdir():
        if path.name.endswith(".json"):
            version = path.name.rsplit("_v", 1)[1].removesuffix(".json")
            assert json.loads(path.read_text())["metadata"]["dtradar.schema_version"] == version


def test_every_cell_column_has_a_description_and_a_unit_suffix_where_it_has_a_unit():
    for f in schema.CELL_SCHEMA:
        assert schema.COLUMN_DESCRIPTIONS[f.name]
    unitless = {"ix", "iy", "blocked", "num_paths", "los", "a_re", "a_im"}
    assert all(n in unitless or n.endswith(("_m", "_rad", "_s", "_db")) for n in schema.CELL_COLUMNS)
