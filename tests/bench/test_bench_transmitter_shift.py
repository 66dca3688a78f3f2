"""bench/bench_transmitter_shift.py's measures on a synthetic two-transmitter twin: the changed share per transmitter,
and the *restored* dynamic twin (transmitter 0 as it is, the others put back to the blueprint's)."""

import importlib.util
from pathlib import Path

import numpy as np

from dtradar_data.core.schema import TX_CELL_COLUMNS, tx_column
from dtradar_data.pipeline.synthetic import synthetic_multi_tx_dataset

NX, NY = 8, 6
SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "bench_transmitter_shift.py"


def _script():
    spec = importlib.util.spec_from_file_location("bench_transmitter_shift", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _twins():
    """A blueprint heard everywhere by both transmitters, and a 'dynamic' twin in which an object blocks one cell
    and silences transmitter 1 in the two columns on the right."""
    blueprint = synthetic_multi_tx_dataset(NX, NY)
    blocked = np.zeros((NY, NX), bool)
    blocked[2, 3] = True
    heard = np.ones((2, NY, NX), bool)
    heard[1, :, -2:] = False
    dynamic = synthetic_multi_tx_dataset(NX, NY, blocked, heard=heard, name="synthetic-tx/dynamic")
    return blueprint, dynamic


def test_only_the_transmitter_whose_cells_changed_counts_them():
    shift = _script()
    blueprint, dynamic = _twins()
    shares = shift.shares(blueprint, dynamic, threshold_db=1.0)
    free = NX * NY - 1
    assert shares["free_cells"] == free
    assert shares["tx0"] == 0.0, "the blocked cell is left out; transmitter 0 hears the rest as before"
    assert shares["tx1"] == shares["any"] == 2 * NY / free


def test_the_restored_twin_takes_the_other_transmitters_from_the_blueprint_and_keeps_transmitter_zero():
    shift = _script()
    blueprint, dynamic = _twins()
    fixed = shift.restored(blueprint, dynamic)
    assert fixed.table.column_names == dynamic.table.column_names
    free = ~dynamic.blocked.ravel()
    for name in TX_CELL_COLUMNS:
        one = tx_column(name, 1)
        got = np.array(fixed.table.column(one).to_pylist(), dtype=object)
        assert list(got[free]) == list(np.array(blueprint.table.column(one).to_pylist(), dtype=object)[free])
        assert list(got[~free]) == list(np.array(dynamic.table.column(one).to_pylist(), dtype=object)[~free])
        assert fixed.table.column(name).equals(dynamic.table.column(name))
    assert shift.shares(blueprint, fixed, threshold_db=1.0)["any"] == 0.0
