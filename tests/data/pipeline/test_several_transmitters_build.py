"""A twin with several transmitters traced end to end with the real ray tracer: the street canyon with one at each
end, a handful of cells and few rays. One trace covers both; transmitter 0's columns are the one-transmitter twin's."""

import numpy as np
import pytest

pytestmark = pytest.mark.sionna

SCENE = """format = 1
[scene]
name = "{name}"
title = "Canyon"
[xml]
path = "sionna:simple_street_canyon"
[grid]
x0_m = -30.0
y0_m = -20.0
cell_m = 5.0
nx = 12
ny = 9
"""
WEST = '[[tx]]\nname = "west"\nposition_m = [-30.0, 0.0, 20.0]\n'
EAST = '[[tx]]\nname = "east"\nposition_m = [30.0, 0.0, 20.0]\n'


def _build(tmp_path, name: str, txs: str):
    from dtradar_data.pipeline.builder import build
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    path = tmp_path / f"{name}.toml"
    path.write_text(SCENE.format(name=name) + txs)
    cfg = BuildConfig(
        scene=str(path),
        coverage_map=False,
        progress=False,
        rt=RTSettings(max_depth=1, samples_per_src=1_000, device="cpu"),
    )
    (ds,) = build(cfg)
    return ds


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_two_transmitters_trace_together_and_leave_transmitter_zero_as_the_one_transmitter_twin_has_it(root, tmp_path):
    import dtradar_data

    one = _build(tmp_path, "canyon-one", WEST)
    two = _build(tmp_path, "canyon-two", WEST + EAST)
    assert (one.transmitters, two.transmitters) == (1, 2)
    for col in one.table.column_names:  # adding a transmitter changes nothing of transmitter 0's
        a = one.table.column(col).to_numpy(zero_copy_only=False)
        b = two.table.column(col).to_numpy(zero_copy_only=False)
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), col
    free = ~two.blocked
    west, east = (two.grid([c])[..., 0] for c in ("tau_s", "tx1_tau_s"))  # each end is nearer its own
    assert np.nanmean(west[:, :3][free[:, :3]]) < np.nanmean(east[:, :3][free[:, :3]])
    assert np.nanmean(east[:, -3:][free[:, -3:]]) < np.nanmean(west[:, -3:][free[:, -3:]])
    loaded = dtradar_data.load("canyon-two/blueprint", paths=True)
    assert loaded.version == two.version and loaded.meta["transmitters"][1]["name"] == "east"
    assert sorted(set(loaded.paths_table.column("tx").to_pylist())) == [0, 1]
    assert loaded.meta["stats"]["num_with_paths_per_tx"][1] > 0
    card = (loaded.path / "README.md").read_text()
    assert "| 1 | east | `tx1_` |" in card and "`tx1_path_gain_db`" in card
    assert one.meta.get("transmitters") is None and "multi_tx_schema_version" not in one.meta.get("build_inputs", {})
