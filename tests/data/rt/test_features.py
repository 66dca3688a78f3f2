"""The path → per-cell reduction, on hand-made path batches (no ray tracer)."""

import numpy as np
import pytest

from dtradar_data.core.schema import CELL_COLUMNS, CELL_SCHEMA, PATH_SCHEMA
from dtradar_data.rt import features
from dtradar_data.rt.tracer import PathBatch

F = 2.4e9


def make_batch():
    # receiver 0: LoS (weaker) + a reflection (stronger); receiver 1: no path; receiver 2: one diffuse path
    valid = np.array([[True, True, False], [False, False, False], [False, True, False]])
    gain = np.array([[1e-6, 4e-6, 0.0], [0, 0, 0], [0, 1e-8, 0]])
    a = np.sqrt(gain).astype(np.complex64)
    tau = np.array([[10e-9, 20e-9, -1], [-1, -1, -1], [-1, 30e-9, -1]])
    ang = np.array([[0.1, 0.2, 0.0], [0, 0, 0], [0, 0.3, 0]])
    inter = np.zeros((2, 3, 3), np.uint32)
    inter[0, 0, 1] = 1  # receiver 0, path 1: one specular reflection
    inter[:, 2, 1] = [1, 2]  # receiver 2, path 1: specular then diffuse
    return PathBatch(
        valid=valid,
        a=a,
        gain=gain,
        tau=tau,
        theta_t=ang,
        phi_t=ang + 1,
        theta_r=ang + 2,
        phi_r=ang + 3,
        interactions=inter,
        frequency_hz=F,
    )


def test_the_strongest_path_is_chosen_by_power_not_by_order():
    c = features.reduce_cells(make_batch())
    assert c["tau_s"][0] == pytest.approx(20e-9)
    assert c["aod_zen_rad"][0] == pytest.approx(0.2) and c["aoa_az_rad"][0] == pytest.approx(3.2)
    assert not c["los"][0], "the strongest path of receiver 0 is a reflection"
    assert list(c["num_paths"]) == [2, 0, 1]


def test_total_gain_sums_all_paths_and_delay_spread_is_power_weighted():
    c = features.reduce_cells(make_batch())
    assert c["path_gain_db"][0] == pytest.approx(10 * np.log10(5e-6))
    mean = (1e-6 * 10e-9 + 4e-6 * 20e-9) / 5e-6
    rms = np.sqrt((1e-6 * 10e-9**2 + 4e-6 * 20e-9**2) / 5e-6 - mean**2)
    assert c["delay_spread_s"][0] == pytest.approx(rms)
    assert c["delay_spread_s"][2] == pytest.approx(0.0, abs=1e-15)


def test_the_coefficient_carries_the_carrier_phase_of_its_delay():
    c = features.reduce_cells(make_batch())
    expected = 2e-3 * np.exp(-2j * np.pi * F * 20e-9)
    assert complex(c["a_re"][0], c["a_im"][0]) == pytest.approx(expected, rel=1e-5)
    assert c["phase_rad"][0] == pytest.approx(np.angle(expected), abs=1e-5)


def test_a_receiver_without_paths_gets_nan_features_and_no_los():
    c = features.reduce_cells(make_batch())
    for key in ("path_gain_db", "a_re", "tau_s", "aod_az_rad", "delay_spread_s"):
        assert np.isnan(c[key][1]), key
    assert not c["los"][1]


def test_per_path_rows_are_strongest_first_with_interaction_letters():
    rows = features.path_rows(make_batch(), ix=np.array([5, 6, 7]), iy=np.array([1, 1, 1]))
    assert list(rows["ix"]) == [5, 5, 7]
    assert list(rows["path"]) == [0, 1, 0]
    assert list(rows["interactions"]) == ["S", "", "S-D"]
    assert list(rows["depth"]) == [1, 0, 2]
    table = features.paths_table([rows])
    assert table.schema.equals(PATH_SCHEMA)
    assert table.num_rows == 3


def test_the_cell_table_has_every_cell_and_nulls_for_blocked_ones():
    blocked = np.array([[False, True], [False, False]])
    free = {k: v for k, v in features.reduce_cells(make_batch()).items()}
    table = features.cells_table(np.array([0.25, 0.75]), np.array([0.25, 0.75]), blocked, free)
    assert table.schema.equals(CELL_SCHEMA) and tuple(table.column_names) == CELL_COLUMNS
    assert table.num_rows == 4
    assert table.column("blocked").to_pylist() == [False, True, False, False]
    assert table.column("num_paths").to_pylist() == [2, 0, 0, 1]
    assert table.column("path_gain_db").null_count == 2  # the blocked cell and the cell without paths
    assert table.column("x_m").to_pylist() == [0.25, 0.75, 0.25, 0.75]
    assert table.column("iy").to_pylist() == [0, 0, 1, 1]


def test_a_feature_count_that_does_not_match_the_free_cells_is_rejected():
    blocked = np.zeros((2, 2), bool)
    with pytest.raises(ValueError, match="free cells"):
        features.cells_table(np.zeros(2), np.zeros(2), blocked, features.reduce_cells(make_batch()))
