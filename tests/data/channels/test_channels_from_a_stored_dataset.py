"""A version built with ``--rt.path-channels`` stores, loads and verifies with its channel columns, and gives channels;
one built without them still loads, and asking it for channels says to rebuild (needs Sionna)."""

from dataclasses import replace

import numpy as np
import pytest

from dtradar_data.core.schema import CHANNEL_PATH_COLUMNS, PATH_COLUMNS

pytestmark = pytest.mark.sionna


def _config(path_channels: bool):
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    rt = RTSettings(max_depth=2, samples_per_src=2_000, device="cpu", path_channels=path_channels)
    return BuildConfig(scene="cubicle", rt=rt, coverage_map=False, progress=False)


@pytest.fixture
def small_cubicle():
    """The real cubicle blueprint, cut down to a 6 x 4 cell corner of the grid so it traces in a second."""
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("cubicle", "blueprint")
    return replace(spec, grid=replace(spec.grid, nx=6, ny=4))


def test_a_version_with_the_channel_columns_round_trips_and_gives_the_stored_reference_coefficients(
    root, small_cubicle
):
    import dtradar_data
    from dtradar_data.channels import Array, ChannelGenerator
    from dtradar_data.pipeline.static_build import build_one
    from dtradar_data.store.local import verify_dir

    built = build_one(small_cubicle, _config(True))
    ds = dtradar_data.load("cubicle/blueprint", revision=built.version, paths=True)
    assert ds.paths_table.column_names == [*PATH_COLUMNS, *CHANNEL_PATH_COLUMNS]
    assert ds.meta["rt"]["path_channels"] and verify_dir(ds.path) == []
    assert "pol_vv_re" in (ds.path / "README.md").read_text(), "the card documents the channel columns"
    # the dataset's own arrays at its reference ports (RX 0, TX 0) give back its stored per-path coefficients
    tx = ds.meta["transmitter"]
    own = Array(tx["num_rows"], tx["num_cols"], tx["pattern"], tx["polarization"])
    rx = Array(1, 1, ds.meta["rt"]["rx_pattern"], ds.meta["rt"]["rx_polarization"])
    out = ChannelGenerator(ds, own, rx, normalize_delays=False).generate()
    paths = ds.paths_table
    stored = paths.column("a_re").to_numpy() + 1j * paths.column("a_im").to_numpy()
    generated = np.concatenate([out.a[c, 0, 0, : out.num_paths[c]] for c in range(len(out.ix))])
    assert len(generated) == len(stored) == paths.num_rows
    nmse = np.sum(np.abs(generated - stored) ** 2) / np.sum(np.abs(stored) ** 2)
    assert 10 * np.log10(nmse) < -60


def test_a_version_without_the_channel_columns_keeps_its_version_loads_and_says_to_rebuild(root, small_cubicle):
    import dtradar_data
    from dtradar_data.channels import Array, ChannelGenerator
    from dtradar_data.core.errors import MissingChannelDataError
    from dtradar_data.pipeline.inputs import build_inputs
    from dtradar_data.store.versions import version_id

    plain, channels = _config(False), _config(True)
    assert "path_channels" not in plain.rt.hashed(), "versions built before the option keep their hashes"
    assert version_id(build_inputs(small_cubicle, plain)) != version_id(build_inputs(small_cubicle, channels))
    from dtradar_data.pipeline.static_build import build_one

    built = build_one(small_cubicle, plain)
    ds = dtradar_data.load("cubicle/blueprint", revision=built.version, paths=True)
    assert ds.paths_table.column_names == list(PATH_COLUMNS)
    with pytest.raises(MissingChannelDataError, match="--rt.path-channels") as caught:
        ChannelGenerator(ds, Array(), Array()).generate()
    assert "rebuild" in caught.value.hint


def test_the_channels_command_writes_the_frequency_response_and_refuses_a_version_without_the_columns(
    root, small_cubicle, tmp_path, capsys
):
    from dtradar_data import cli
    from dtradar_data.pipeline.static_build import build_one

    with_columns = build_one(small_cubicle, _config(True))
    out = tmp_path / "ch.npz"
    args = ["channels", f"cubicle/blueprint@{with_columns.version}", "--out", str(out), "--subcarriers", "8"]
    assert cli.main([*args, "--tx-rows", "4", "--tx-cols", "4", "--rx-cols", "2", "--cir"]) == 0
    with np.load(out) as z:
        cells = int((~with_columns.blocked).sum())
        assert z["h"].shape == (cells, 2, 32, 8) and z["a"].shape[:3] == (cells, 2, 32)
        assert (z["num_paths"] > 0).all() and z["carrier_hz"] == with_columns.meta["rt"]["frequency_hz"]
    plain = build_one(small_cubicle, _config(False))
    capsys.readouterr()
    assert cli.main(["channels", f"cubicle/blueprint@{plain.version}", "--out", str(tmp_path / "no.npz")]) == 2
    err = capsys.readouterr().err
    assert "--rt.path-channels" in err and "build --scene cubicle --variant blueprint" in err
    assert not (tmp_path / "no.npz").exists()
