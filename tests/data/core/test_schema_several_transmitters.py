"""The several-transmitter extension of the per-cell and per-path schemas: transmitter 0 keeps the static columns,
transmitter k adds ``tx{k}_`` copies of the radio columns after them; one transmitter is the static schema itself."""

import pytest

from dtradar_data.core.schema import (
    CELL_SCHEMA,
    PATH_SCHEMA,
    TX_CELL_COLUMNS,
    cell_schema,
    meta_transmitters,
    path_schema,
    tx_column,
)


def test_one_transmitter_is_the_static_schema_itself():
    assert cell_schema(False, 1) is CELL_SCHEMA and path_schema(False, 1) is PATH_SCHEMA


def test_three_transmitters_append_two_prefixed_copies_of_the_radio_columns_in_order():
    schema = cell_schema(False, 3)
    assert schema.names[: len(CELL_SCHEMA)] == CELL_SCHEMA.names
    extra = schema.names[len(CELL_SCHEMA) :]
    assert extra == [tx_column(c, k) for k in (1, 2) for c in TX_CELL_COLUMNS]
    assert schema.field("tx2_num_paths").nullable is False and schema.field("tx2_a_re").nullable is True
    assert schema.metadata[b"dtradar.transmitters"] == b"3"
    assert (schema.field("tx1_tau_s").metadata[b"description"]).startswith(b"transmitter 1: ")


def test_the_per_path_table_of_several_transmitters_has_a_tx_column_before_path():
    names = path_schema(False, 2).names
    assert names[:4] == ["ix", "iy", "tx", "path"] and names[4:] == PATH_SCHEMA.names[3:]


def test_a_moving_twin_or_zero_transmitters_is_refused():
    with pytest.raises(ValueError, match="moving twin has one transmitter"):
        cell_schema(True, 2)
    with pytest.raises(ValueError, match="1 or more transmitters"):
        path_schema(False, 0)


def test_a_stored_version_counts_its_transmitters_from_its_list_and_one_without_it():
    assert meta_transmitters({}) == 1 and meta_transmitters({"transmitters": [{}, {}, {}]}) == 3
