"""End to end: a tiny scene is traced, stored as a versioned dataset, loaded by name, and reused (needs Sionna)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from dtradar_data.core.schema import CELL_COLUMNS

pytestmark = pytest.mark.sionna


@pytest.fixture
def config():
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    return BuildConfig(
        scene="cubicle",
        rt=RTSettings(max_depth=1, samples_per_src=2_000, device="cpu"),
        coverage_samples=20_000,
        progress=False,
    )


@pytest.fixture
def small_cubicle():
    """The real cubicle blueprint, cut down to a 6 x 4 cell corner of the grid so it traces in a second."""
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("cubicle", "blueprint")
    return replace(spec, grid=replace(spec.grid, nx=6, ny=4))


def test_a_built_dataset_loads_by_name_with_every_column_and_a_coverage_map(root, config, small_cubicle):
    import dtradar_data
    from dtradar_data.pipeline.static_build import build_one

    ds = build_one(small_cubicle, config)
    loaded = dtradar_data.load("cubicle/blueprint")
    assert loaded.version == ds.version and loaded.table.equals(ds.table)
    assert tuple(loaded.table.column_names) == CELL_COLUMNS
    assert loaded.grid().shape == (4, 6, 10) and loaded.blocked.shape == (4, 6)
    free = ~loaded.blocked
    assert (loaded.frame["num_paths"].to_numpy().reshape(4, 6)[free] > 0).all(), "every free cell has a path"
    assert (loaded.path / "coverage.png").stat().st_size > 1000
    assert (loaded.path / "paths.parquet").exists()
    meta = json.loads((loaded.path / "meta.json").read_text())
    assert meta["rt"]["max_depth"] == 1 and meta["grid"]["nx"] == 6
    assert meta["scene_hash"] == small_cubicle.digest()
    assert not (root / "work" / "cubicle" / "blueprint" / ds.version).exists(), "work files are cleaned up"


def test_building_the_same_thing_twice_reuses_the_version_and_a_change_makes_a_new_one(
    root, config, small_cubicle, capsys
):
    import dtradar_data
    from dtradar_data.pipeline.static_build import build_one

    first = build_one(small_cubicle, config)
    again = build_one(small_cubicle, config)
    assert again.version == first.version
    assert "already built" in capsys.readouterr().out
    other = build_one(small_cubicle, replace(config, rt=replace(config.rt, seed=7)))
    assert other.version != first.version
    assert dtradar_data.load("cubicle/blueprint", revision=first.version).table.equals(first.table)
    assert dtradar_data.load("cubicle/blueprint").version == other.version


def test_a_failed_build_leaves_the_store_untouched(root, config, small_cubicle, monkeypatch):
    from dtradar_data.pipeline import static_build

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(static_build, "render_coverage_png", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        static_build.build_one(small_cubicle, config)
    assert not (root / "datasets" / "cubicle" / "blueprint").exists() or not any(
        p.is_dir() for p in (root / "datasets" / "cubicle" / "blueprint").iterdir()
    )
    # the traced batches survive, so the next attempt does not trace again
    work = list((root / "work" / "cubicle" / "blueprint").rglob("batch_*.npz"))
    assert work, "finished batches are kept for the retry"
    monkeypatch.undo()
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(root))
    ds = static_build.build_one(small_cubicle, config)
    from dtradar_data.geometry.occupancy import occupancy

    assert ds.table.num_rows == 24
    np.testing.assert_array_equal(ds.blocked, occupancy(small_cubicle))


def test_a_users_scene_file_builds_by_path_and_loads_by_its_name(root, tmp_path, config, tiny_room):
    import dtradar_data
    from dtradar_data.pipeline.builder import build

    path = tmp_path / "my-room.toml"
    path.write_text(tiny_room)
    (ds,) = build(replace(config, scene=str(path), variant="blueprint", coverage_map=False))
    assert ds.name == "tiny-room/blueprint" and ds.table.num_rows == 12
    assert ds.blocked[0, 0] and ds.blocked.sum() == 1
    assert dtradar_data.load("tiny-room/blueprint").version == ds.version
    assert "A user's own 2 m x 1.5 m room" in (ds.path / "README.md").read_text()


def test_two_builds_of_one_version_at_once_both_finish_with_one_version_traced_once(
    root, config, small_cubicle, monkeypatch
):
    import threading

    from dtradar_data.pipeline import static_build, tracing

    traced = []
    real_trace = tracing.trace_grid

    def counting_trace(*args, **kwargs):
        traced.append(threading.get_ident())
        return real_trace(*args, **kwargs)

    monkeypatch.setattr(tracing, "trace_grid", counting_trace)
    cfg = replace(config, coverage_map=False)
    results, errors = [], []

    def run():
        try:
            results.append(static_build.build_one(small_cubicle, cfg))
        except BaseException as e:  # noqa: BLE001 - the assertion below reports it
            errors.append(e)

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(results) == 2 and len(traced) == 1
    assert results[0].version == results[1].version
    stored = [p for p in (root / "datasets" / "cubicle" / "blueprint").iterdir() if p.is_dir()]
    assert len(stored) == 1
