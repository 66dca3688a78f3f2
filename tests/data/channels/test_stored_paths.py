"""The channel columns' schema and the per-path reader, without the ray tracer."""

from importlib import resources

import numpy as np
import pyarrow as pa
import pytest

from dtradar_data.channels import StoredPaths, ofdm_frequencies
from dtradar_data.core import schema
from dtradar_data.core.errors import InvalidSettingError, MissingChannelDataError


def test_the_channel_schema_equals_its_golden_file_and_extends_the_static_one():
    golden = resources.files("dtradar_data.core") / "golden" / f"paths_channels_v{schema.CHANNEL_SCHEMA_VERSION}.json"
    current = schema.path_schema(False, 1, channels=True)
    assert schema.schema_to_json(current) == golden.read_text(), "bump CHANNEL_SCHEMA_VERSION with a new golden file"
    assert current.names == [*schema.PATH_COLUMNS, *schema.CHANNEL_PATH_COLUMNS]
    several = schema.path_schema(False, 3, channels=True)
    assert several.names[:3] == ["ix", "iy", "tx"] and several.metadata[b"dtradar.transmitters"] == b"3"
    with pytest.raises(ValueError, match="moving"):
        schema.path_schema(True, 1, channels=True)


def test_only_a_version_whose_settings_name_path_channels_has_the_columns():
    assert not schema.meta_path_channels({"rt": {"max_depth": 5}}) and not schema.meta_path_channels({})
    assert schema.meta_path_channels({"rt": {"path_channels": "dtradar-1 ..."}})


def _table(rows):
    """A per-path table with the channel columns: ``rows`` of ``(ix, iy, path, tau_s, vv)``."""
    cols = {f.name: [] for f in schema.path_schema(False, 1, channels=True)}
    for ix, iy, path, tau, vv in rows:
        for name in cols:
            cols[name].append(0.0)
        cols["ix"][-1], cols["iy"][-1], cols["path"][-1], cols["tau_s"][-1] = ix, iy, path, tau
        cols["pol_vv_re"][-1], cols["depth"][-1], cols["interactions"][-1], cols["vertices_m"][-1] = vv, 0, "", []
    return pa.Table.from_pydict(cols, schema=schema.path_schema(False, 1, channels=True))


def test_stored_paths_come_cell_by_cell_in_the_order_asked_strongest_first():
    table = _table([(0, 0, 0, 1e-8, 1.0), (0, 0, 1, 2e-8, 0.5), (1, 0, 0, 3e-8, 2.0), (0, 1, 0, 4e-8, 3.0)])
    sp = StoredPaths.from_table(table, [(0, 1), (0, 0), (2, 2)])
    assert sp.num_cells == 3 and list(sp.counts) == [1, 2, 0], "a cell without paths has none"
    assert list(sp.cell) == [0, 1, 1]
    np.testing.assert_allclose(sp.tau_s, [4e-8, 1e-8, 2e-8], rtol=1e-6)
    assert sp.transfer[:, 0, 0].real.tolist() == [3.0, 1.0, 0.5]


def test_a_table_without_the_channel_columns_raises_a_typed_error_saying_to_rebuild():
    plain = pa.Table.from_pydict({f.name: [] for f in schema.PATH_SCHEMA}, schema=schema.PATH_SCHEMA)
    with pytest.raises(MissingChannelDataError) as caught:
        StoredPaths.from_table(plain, [(0, 0)], name="cubicle/blueprint@v0")
    assert "cubicle/blueprint@v0" in str(caught.value) and "--rt.path-channels" in caught.value.hint
    assert isinstance(caught.value, LookupError)


def test_ofdm_frequencies_are_sionnas_subcarrier_grid():
    assert ofdm_frequencies(4, 10.0).tolist() == [-20.0, -10.0, 0.0, 10.0]
    assert ofdm_frequencies(3, 10.0).tolist() == [-10.0, 0.0, 10.0]
    with pytest.raises(InvalidSettingError):
        ofdm_frequencies(0, 10.0)
