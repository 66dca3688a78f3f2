"""The version record: today's meta.json round-trips, older records migrate, damaged or newer ones fail clearly."""

import pytest

from dtradar_data.core.errors import CorruptDatasetError
from dtradar_data.core.record import RECORD_FORMAT, VersionRecord

BASE = {
    "name": "cubicle/blueprint",
    "scene": "cubicle",
    "variant": "blueprint",
    "version": "0123456789abcdef",
    "schema_version": 1,
}


def test_a_record_round_trips_through_its_json_and_keeps_unknown_keys():
    meta = {
        **BASE,
        "record_format": RECORD_FORMAT,
        "title": "Cubicle",
        "footprints": {"buildings": 64},
        "files": {"cells.parquet": {"sha256": "ab" * 32, "bytes": 10}},
    }
    rec = VersionRecord.from_meta(meta)
    assert rec.title == "Cubicle" and rec.files["cells.parquet"].bytes == 10
    assert VersionRecord.from_meta(rec.to_meta()) == rec
    assert rec.to_meta()["footprints"] == {"buildings": 64}


def test_a_record_without_a_format_takes_its_scene_fields_from_the_scene_spec():
    spec = {"title": "Old title", "licence": "CC-BY-4.0", "grid": {"nx": 3, "ny": 2}, "tx": {"power_dbm": 20}}
    rec = VersionRecord.from_meta({**BASE, "scene_spec": spec})
    assert rec.record_format == RECORD_FORMAT
    assert (rec.title, rec.licence, rec.transmitter, rec.num_rows) == ("Old title", "CC-BY-4.0", {"power_dbm": 20}, 6)


def test_a_record_of_a_newer_format_says_to_upgrade():
    with pytest.raises(CorruptDatasetError, match="format 99") as err:
        VersionRecord.from_meta({**BASE, "record_format": 99})
    assert "upgrade dtradar" in str(err.value)


@pytest.mark.parametrize("damage", [{"version": None}, {"schema_version": "one"}, {"files": {"x": {"sha256": 1}}}])
def test_a_damaged_record_names_the_field_and_the_file(damage):
    with pytest.raises(CorruptDatasetError, match="meta.json: field") as err:
        VersionRecord.from_meta({**BASE, **damage}, where="/data/meta.json")
    assert "/data/meta.json" in str(err.value) and "rebuild" in str(err.value)
