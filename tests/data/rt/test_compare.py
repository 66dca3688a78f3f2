"""The strongest-path agreement rule shared by the benchmarks and the differential-build test (tiny tables)."""

import dataclasses

import numpy as np
import pyarrow as pa
import pytest

from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.rt.compare import compare


def with_column(ds, name, values):
    table = ds.table.set_column(ds.table.schema.get_field_index(name), name, pa.array(values))
    return dataclasses.replace(ds, table=table)


@pytest.fixture
def ds():
    blocked = np.zeros((6, 8), bool)
    blocked[2, 3] = True
    return synthetic_dataset(8, 6, blocked)


def test_a_table_agrees_with_itself_everywhere(ds):
    c = compare(ds, ds)
    assert c["agree"].all() and c["free"].sum() == 47
    assert np.nanmax(c["gain_diff_db"]) == 0.0


def test_a_departure_angle_off_by_more_than_a_degree_or_a_later_delay_is_a_different_path(ds):
    zen = ds.table.column("aod_zen_rad").to_numpy(zero_copy_only=False).astype(float)
    tau = ds.table.column("tau_s").to_numpy(zero_copy_only=False).astype(float)
    zen2, tau2 = zen.copy(), tau.copy()
    zen2[0] += np.deg2rad(2.0)
    zen2[1] += np.deg2rad(0.5)  # within the tolerance
    tau2[2] += 1e-9
    got = with_column(with_column(ds, "aod_zen_rad", zen2), "tau_s", tau2)
    agree = compare(ds, got)["agree"]
    assert not agree[0] and agree[1] and not agree[2] and agree[3:].all()


def test_a_cell_with_a_path_in_one_trace_only_disagrees_and_one_without_in_both_agrees(ds):
    tau = ds.table.column("tau_s").to_numpy(zero_copy_only=False).astype(float)
    lost = tau.copy()
    lost[5] = np.nan
    agree = compare(ds, with_column(ds, "tau_s", lost))["agree"]
    assert not agree[5] and agree[2 * 8 + 3]  # the blocked cell has no path in either


def test_grids_of_different_shapes_cannot_be_compared(ds):
    with pytest.raises(ValueError, match="shapes"):
        compare(ds, synthetic_dataset(4, 4))


def test_a_comparison_summary_counts_free_cells_only_and_skips_cells_without_gain():
    import numpy as np

    from dtradar_data.rt.compare import summarize

    c = {
        "agree": np.array([True, False, True, True]),
        "gain_diff_db": np.array([0.5, 1.0, np.nan, 9.0]),
        "free": np.array([True, True, True, False]),
    }
    s = summarize(c)
    assert s["cells"] == 3 and s["agreement"] == 2 / 3 and s["gain_median_db"] == 0.75
    assert summarize(c, np.array([False, True, False, True]))["agreement"] == 0.0
    assert np.isnan(summarize(c, np.zeros(4, bool))["agreement"])
