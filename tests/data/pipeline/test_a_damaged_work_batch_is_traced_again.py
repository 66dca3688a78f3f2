"""A finished batch in a build's work folder (``batch_<b>.npz``) is checked for content as the solve cache is: it
carries the sha256 of its arrays, and a file damaged in place (the middle third overwritten with random bytes of the
same size) or cut short is not read into the table (it raised a raw zip error, or was served) but traced again and
rewritten, with one line naming the file. A sound one is served as it is, silently."""

import numpy as np
import pytest

from dtradar_data.pipeline import tracing
from dtradar_data.pipeline.batches import DamagedBatchError, load_batch, save_batch

CELLS = {"rss_dbm": np.linspace(-90, -40, 64).astype(np.float32), "n_paths": np.arange(64, dtype=np.int32)}
PATHS = {"delay_s": np.linspace(0, 1e-6, 200)}


def middle_third_random(path):
    data = bytearray(path.read_bytes())
    n = len(data) // 3
    data[n : 2 * n] = np.random.default_rng(0).integers(0, 256, n, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))


def cut_in_half(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def one_value_changed(path):
    """Damage a zip's CRC-32 alone would miss: the stored bytes of one value changed, CRC fixed to match."""
    import zipfile

    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    raw = bytearray(members["c_rss_dbm.npy"])
    raw[-4:] = np.float32(0.0).tobytes()
    members["c_rss_dbm.npy"] = bytes(raw)
    with zipfile.ZipFile(path, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)


@pytest.mark.parametrize("damage", [middle_third_random, cut_in_half, one_value_changed])
def test_a_damaged_batch_is_named_and_traced_again(tmp_path, damage, monkeypatch, capsys):
    path = tmp_path / "batch_00000.npz"
    save_batch(path, CELLS, PATHS)
    damage(path)
    with pytest.raises(DamagedBatchError, match="batch_00000.npz"):
        load_batch(path)
    traced = []

    def trace(tracer, points, ix, iy, *, per_path):
        traced.append(len(points))
        return CELLS, PATHS

    monkeypatch.setattr(tracing, "trace_batch", trace)
    rx = tracing._Receivers(None, None, None, np.arange(64), np.arange(64), np.zeros((64, 3)))
    cells, paths, _ = tracing._load_or_trace(path, None, None, rx, slice(0, 64), object(), per_path=True)
    assert traced == [64], "traced again"
    np.testing.assert_array_equal(cells["rss_dbm"], CELLS["rss_dbm"])
    err = capsys.readouterr().err
    assert f"a finished batch cannot be used: {path}" in err and "tracing it again" in err, err
    back, _ = load_batch(path)  # rewritten whole
    np.testing.assert_array_equal(back["n_paths"], CELLS["n_paths"])


def test_a_sound_batch_is_served_silently_and_leaves_no_temp_file(tmp_path, capsys):
    path = tmp_path / "batch_00001.npz"
    save_batch(path, CELLS, PATHS)
    cells, paths = load_batch(path)
    np.testing.assert_array_equal(cells["rss_dbm"], CELLS["rss_dbm"])
    np.testing.assert_array_equal(paths["delay_s"], PATHS["delay_s"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["batch_00001.npz"]
    assert capsys.readouterr().err == ""
