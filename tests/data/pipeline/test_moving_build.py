"""Moving twins as datasets (real ray tracer, a user's 6 m x 1.5 m corridor with one person walking, two snapshots):
snapshot 1 is re-traced differentially from snapshot 0 and equals a full trace of the same instant in the cells it
re-traced (both traced one cell per batch, so a cell's row does not depend on its batch) and snapshot 0 everywhere
else; the stored table follows the moving-twin contract; an interrupted build resumes at the first missing snapshot;
the twin loads, lists, verifies and has a card with its animation; a build that shares each snapshot's cells with a
helper process stores the same tables and version."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

NAME = "test-corridor/moving"
#: A user's corridor: 12 x 3 cells of 0.5 m, the transmitter at the east end, one person walking to and fro at the
#: west end (0.5 m per 1 s snapshot), so the east cells are out of the re-trace radius and are kept.
CORRIDOR = """
format = 1
[scene]
name = "test-corridor"
title = "Test corridor"
description = "A user's own 6 m x 1.5 m corridor with one box"
source = "test"
licence = "CC0-1.0"
attribution = "nobody"
[room]
width_m = 6.0
length_m = 1.5
height_m = 2.5
wall_thickness_m = 0.2
wall_material = "brick"
floor_material = "concrete"
floor_thickness_m = 0.1
ceiling_material = "concrete"
ceiling_thickness_m = 0.1
[grid]
cell_m = 0.5
nx = 12
ny = 3
[tx]
position_m = [5.5, 0.75, 2.4]
[robot]
rx_height_m = 1.0
robot_height_m = 1.0
[[objects]]
name = "box_01"
kind = "box"
material = "wood"
x_m = 3.25
y_m = 0.25
width_m = 0.4
length_m = 0.4
height_m = 0.8
[moving]
description = "One person walking to and fro at the west end"
dt_s = 1.0
horizon_s = 2.0
[[moving.mover]]
name = "walker"
kind = "person"
speed_mps = 0.5
mode = "back-and-forth"
waypoints = [[0.75, 0.75], [2.25, 0.75]]
"""


def _config(path, **rt):
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    settings = {"max_depth": 1, "samples_per_src": 2_000, "device": "cpu", **rt}
    return BuildConfig(scene=str(path), variant="moving", rt=RTSettings(**settings), progress=False)


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "corridor.toml"
    path.write_text(CORRIDOR)
    return path


@pytest.fixture(scope="module")
def built(tmp_path_factory, corridor):
    """The corridor's moving twin built once, one cell per trace batch, in a data root of its own."""
    from dtradar_data.pipeline.builder import build

    root = tmp_path_factory.mktemp("root")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(root))
        config = _config(corridor, batch_size=1)
        (ds,) = build(config)
        yield ds, config, root, corridor


@pytest.fixture
def in_built_root(built, monkeypatch):
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(built[2]))
    return built


def _col(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy(zero_copy_only=False)


@pytest.mark.sionna
def test_a_differential_snapshot_equals_a_full_trace_where_it_re_traced_and_the_previous_snapshot_elsewhere(
    in_built_root,
):
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.pipeline.differential import retrace_mask
    from dtradar_data.pipeline.tracing import trace_grid
    from dtradar_data.rt.features import CELL_RADIO_KEYS
    from dtradar_data.scenes import load_moving_scene

    ds, config, _, corridor = in_built_root
    moving = load_moving_scene(corridor)
    s0, s1 = ds.snapshot(0).table, ds.snapshot(1).table
    spec0, spec1 = moving.spec_at(0), moving.spec_at(1)
    changes = moving.changed_between(0, 1)
    assert [c.name for c in changes] == ["walker"]
    mask, reasons = retrace_mask(
        spec0,
        spec1,
        s0,
        radius_m=config.retrace_radius_m,
        changed=[c.before for c in changes] + [c.after for c in changes],
    )
    record = ds.meta["moving_build"]["per_snapshot"]
    assert [r["mode"] for r in record] == ["full", "differential"]
    assert record[1]["retraced_cells"] == int(mask.sum()) and record[1]["movers_moved"] == ["walker"]
    blocked1 = occupancy(spec1)
    assert np.array_equal(_col(s1, "blocked").reshape(blocked1.shape), blocked1)
    freed = occupancy(spec0) & ~blocked1  # where the walker stood at t = 0
    assert freed.any() and (mask[freed]).all(), "a cell the mover left is re-traced"

    full, full_paths, _, tracer = trace_grid(spec1, config.rt, per_path=True, progress=False)
    tracer.close()
    retraced, kept = mask.ravel(), ~mask.ravel() & ~blocked1.ravel()
    assert retraced.sum() > 0 and kept.sum() >= 5, "the corridor must have both re-traced and kept cells"
    for key in CELL_RADIO_KEYS:
        got, want_full, want_prev = _col(s1, key), _col(full, key), _col(s0, key)
        np.testing.assert_array_equal(got[retraced], want_full[retraced], err_msg=key)
        np.testing.assert_array_equal(got[kept], want_prev[kept], err_msg=key)

    loaded = _load(paths=True)
    paths = loaded.paths_table
    p1 = paths.filter(pc.equal(paths.column("t"), 1)).drop_columns(["t"])
    p0 = paths.filter(pc.equal(paths.column("t"), 0)).drop_columns(["t"])

    def rows(table, cells):
        keep = cells[_col(table, "iy"), _col(table, "ix")]
        order = [("iy", "ascending"), ("ix", "ascending"), ("path", "ascending")]
        return table.filter(pa.array(keep)).sort_by(order).to_pydict()

    assert rows(p1, mask) == rows(full_paths, mask), "re-traced cells have the full trace's paths"
    kept_cells = ~mask & ~blocked1
    assert rows(p1, kept_cells) == rows(p0, kept_cells), "kept cells keep snapshot 0's paths"


def _load(**kwargs):
    import dtradar_data

    return dtradar_data.load(NAME, **kwargs)


@pytest.mark.sionna
def test_the_stored_moving_twin_follows_the_table_contract(in_built_root):
    from dtradar_data.core.schema import MOVING_CELL_SCHEMA
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.pipeline.moving import mover_mask
    from dtradar_data.pipeline.synthetic import synthetic_moving_dataset
    from dtradar_data.scenes import load_moving_scene

    ds, _, _, corridor = in_built_root
    moving = load_moving_scene(corridor)
    t = ds.table
    assert t.schema.names == MOVING_CELL_SCHEMA.names
    synthetic = synthetic_moving_dataset(4, 3, snapshots=2)
    assert {f.name: f.type for f in t.schema} == {f.name: f.type for f in synthetic.table.schema}
    assert ds.meta["moving"] == {"snapshots": 2, "dt_s": 1.0, "movers": ["walker"]}
    assert set(ds.meta["moving"]) == set(synthetic.meta["moving"])
    h, w = 3, 12
    assert t.num_rows == 2 * h * w and ds.is_moving and ds.snapshots == 2
    tt, iy, ix = _col(t, "t"), _col(t, "iy"), _col(t, "ix")
    assert np.array_equal(tt, np.repeat([0, 1], h * w))
    assert np.array_equal(iy * w + ix, np.tile(np.arange(h * w), 2)), "rows sorted by (t, iy, ix)"
    blocked, mover = _col(t, "blocked"), _col(t, "mover")
    assert mover.any() and not (mover & ~blocked).any(), "mover is a subset of blocked"
    for k in range(2):
        sl = slice(k * h * w, (k + 1) * h * w)
        assert np.array_equal(mover[sl], mover_mask(moving, k).ravel())
        assert np.array_equal(blocked[sl], occupancy(moving.spec_at(k)).ravel())
    assert not np.array_equal(mover[: h * w], mover[h * w :]), "the walker moved"
    for key in ("path_gain_db", "tau_s", "aod_az_rad"):
        assert t.column(key).filter(pa.array(blocked)).null_count == int(blocked.sum()), key
    snap = ds.snapshot(1)
    assert "t" not in snap.table.column_names and snap.meta["snapshot"] == {"t": 1, "time_s": 1.0}
    assert snap.blocked.shape == (h, w)
    assert ds.meta["moving_schema_version"] == 1 and ds.meta["variant"] == "moving"


@pytest.mark.sionna
def test_the_rl_side_reads_the_built_moving_twin(in_built_root):
    from dtradar_rl.task.moving_masks import moving_masks

    blocked, mover = moving_masks(in_built_root[0])
    assert blocked.shape == (2, 36) and mover.any()


@pytest.mark.sionna
def test_the_moving_twin_loads_by_name_lists_verifies_and_is_reused(in_built_root, capsys):
    from dtradar_data import cli
    from dtradar_data.pipeline.builder import build
    from dtradar_data.pipeline.inputs import moving_build_inputs
    from dtradar_data.scenes import load_moving_scene
    from dtradar_data.store import listing
    from dtradar_data.store.versions import version_id

    ds, config, root, corridor = in_built_root
    loaded = _load()
    assert loaded.version == ds.version and loaded.table.equals(ds.table) and loaded.snapshots == 2
    assert _load(revision="v0").version == ds.version
    moving = load_moving_scene(corridor)
    assert version_id(moving_build_inputs(moving, config)) == ds.version
    assert listing.verify(NAME) == {ds.version: []}
    assert any(e.name == NAME and e.built for e in listing.list_datasets())
    (again,) = build(config)
    assert again.version == ds.version and "already built, reusing it" in capsys.readouterr().out
    assert cli.main(["info", NAME]) == 0
    out = capsys.readouterr().out
    assert "moving:      2 snapshots, 1.0 s apart; movers: walker" in out and "differentially" in out
    assert cli.main(["list"]) == 0 and NAME in capsys.readouterr().out
    assert cli.main(["verify", NAME]) == 0
    assert not (root / "work" / "test-corridor" / "moving" / ds.version).exists(), "work files are cleaned up"


@pytest.mark.sionna
def test_the_card_says_how_the_twin_was_made_and_shows_its_animation(in_built_root):
    from PIL import Image

    ds = in_built_root[0]
    card = (ds.path / "README.md").read_text()
    assert "### Moving twin" in card and "`walker`" in card
    assert "differentially from the one before" in card
    assert "![test-corridor/moving: path gain per cell over time" in card and "(moving.gif)" in card
    assert "| `t` | int32, not null |" in card and "| `mover` | bool, not null |" in card
    record = ds.meta["moving_build"]["per_snapshot"]
    assert f"| 1 | differential | {record[1]['retraced_cells']} | {record[1]['free_cells']} | walker |" in card
    with Image.open(ds.path / "moving.gif") as gif:
        assert gif.format == "GIF" and gif.n_frames == 2
    meta = json.loads((ds.path / "meta.json").read_text())
    assert "moving.gif" in meta["files"]


@pytest.mark.sionna
def test_an_interrupted_build_restarts_at_the_first_missing_snapshot(root, corridor, monkeypatch):
    """Killed while tracing snapshot 1: snapshot 0 is in the work folder, and the next build traces only snapshot 1."""
    import dtradar_data
    from dtradar_data.pipeline import moving
    from dtradar_data.pipeline.builder import build

    config = _config(corridor)
    real = moving.differential_snapshot

    class Killed(Exception):
        pass

    def killed(*args, **kwargs):
        raise Killed("killed while tracing snapshot 1")

    monkeypatch.setattr(moving, "differential_snapshot", killed)
    with pytest.raises(Killed):
        build(config)
    (work,) = [p for p in (root / "work" / "test-corridor" / "moving").iterdir() if p.is_dir()]
    assert moving.snapshot_done(work, 0) and not moving.snapshot_done(work, 1)
    first = (work / "snapshot_00000.cells.parquet").read_bytes()

    def must_not_trace(*args, **kwargs):
        raise AssertionError("snapshot 0 was traced again")

    monkeypatch.setattr(moving, "_full_snapshot", must_not_trace)
    calls = []

    def counted(*args, **kwargs):
        calls.append(args[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(moving, "differential_snapshot", counted)
    (ds,) = build(config)
    assert calls == [1]
    assert ds.version == work.name and not work.exists()
    reused = pq.read_table(pa.BufferReader(first))
    stored = ds.snapshot(0).table
    for key in reused.column_names:  # snapshot 0 as the interrupted build left it
        np.testing.assert_array_equal(_col(stored, key), _col(reused, key), err_msg=key)
    assert dtradar_data.load(NAME).version == ds.version


@pytest.mark.parametrize(
    ("options", "flag"),
    [
        (dict(differential=True), "--differential"),
        (dict(tx_pose_error=(0.5, 5.0)), "--tx-pose-error"),
        (dict(coverage_samples=1000), "--coverage-samples"),
        (dict(coverage_map=False), "--no-coverage-map"),
        (dict(grid=(0.0, 0.0, 1.0, 4, 4)), "--grid"),
    ],
)
def test_the_options_a_moving_build_cannot_use_are_refused_naming_them(options, flag):
    from dtradar_data.core.errors import InvalidSettingError
    from dtradar_data.pipeline.config import BuildConfig

    with pytest.raises(InvalidSettingError) as err:
        BuildConfig(scene="cubicle", variant="moving", **options)
    assert flag in err.value.message and err.value.hint
    assert BuildConfig(scene="cubicle", variant="moving", retrace_radius_m=2.0).retrace_radius_m == 2.0


def test_which_scenes_have_a_moving_twin_to_build():
    from dtradar_data.core.errors import SceneFileError
    from dtradar_data.scenes import build_targets

    assert build_targets("cubicle", "moving") == [("cubicle", "moving")]
    assert build_targets("dallas", "moving") == [("dallas-q3", "moving")]
    assert ("cubicle", "moving") not in build_targets("cubicle", "all")
    with pytest.raises(SceneFileError, match="no moving twin"):
        build_targets("sionna:munich", "moving")


def test_the_moving_variant_is_a_command_line_choice(capsys):
    from dtradar_data import cli

    with pytest.raises(SystemExit):
        cli.main(["build", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "moving" in text and "differentially from the one before" in text


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
@pytest.mark.sionna
def test_a_build_that_shares_its_cells_with_a_helper_process_stores_the_same_tables_and_version(
    built, tmp_path, monkeypatch
):
    """The corridor again, every differential snapshot's cells alternating between the build and one helper."""
    from dtradar_data.pipeline import moving, trace_helpers
    from dtradar_data.pipeline.builder import build

    ds, config, root, _ = built
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(root))
    want_paths = _load(paths=True).paths_table
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "root"))
    monkeypatch.setattr(trace_helpers, "MIN_CELLS_PER_PART", 1)
    monkeypatch.setattr(moving, "helper_count", lambda *args, **kwargs: 1)
    shared = []
    real = trace_helpers.TraceHelpers.trace

    def counted(self, *args, **kwargs):
        shared.append(self.count)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(trace_helpers.TraceHelpers, "trace", counted)
    (again,) = build(config)
    assert shared == [1], "snapshot 1 was shared with the helper"
    assert again.version == ds.version
    assert again.table.equals(ds.table)
    assert _load(paths=True).paths_table.equals(want_paths)
