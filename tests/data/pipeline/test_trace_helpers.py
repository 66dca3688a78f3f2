"""Helper processes trace parts of a re-trace beside the build's process: the parts cover the cells in order, one per
process where each keeps enough cells; there is one helper per core beyond the build's within memory and none with
Sionna's own solver; cells a helper traces are the bytes the build's process traces (the tiny room, real ray
tracer), a helper's error is raised in the build, and a helper that dies leaves its cells to the build's process."""

from __future__ import annotations

import numpy as np
import pytest

from dtradar_data.pipeline import trace_helpers
from dtradar_data.pipeline.trace_helpers import MIN_CELLS_PER_PART, helper_count, parts
from dtradar_data.rt.settings import RTSettings


def _covered(slices: list[slice]) -> list[int]:
    return [i for sl in slices for i in range(sl.start, sl.stop)]


def test_parts_cover_the_cells_in_row_major_order_one_per_process_where_each_keeps_the_minimum():
    settings = RTSettings(batch_size=1024)
    for n in (0, 1, 63, 64, 127, 128, 403, 580, 2100):
        for processes in (1, 2, 3):
            slices = parts(n, settings, processes)
            assert _covered(slices) == list(range(n)), (n, processes)
            sizes = [sl.stop - sl.start for sl in slices]
            assert not sizes or max(sizes) - min(sizes) <= 1, "made even"
            want = max(-(-n // 1024), min(processes, n // MIN_CELLS_PER_PART), 1) if n else 0
            assert len(slices) == want, (n, processes)
    assert [sl.stop - sl.start for sl in parts(403, settings, 2)] == [201, 202]
    assert len(parts(3000, settings, 2)) == 3, "no part above the batch size"


def test_there_is_a_helper_per_core_beyond_this_process_within_memory_and_cells_and_none_with_sionnas_own_solver():
    settings = RTSettings()
    lots = 2**40
    assert helper_count(580, settings, cores=2, memory=lots) == 1
    assert helper_count(580, settings, cores=1, memory=lots) == 0
    assert helper_count(580, settings, cores=16, memory=lots) == 580 // MIN_CELLS_PER_PART - 1, "cells bound it"
    assert helper_count(10_000, settings, cores=16, memory=lots) == 15
    need = trace_helpers.estimate_memory(settings)
    assert helper_count(10_000, settings, cores=16, memory=3 * need) == 2, "this process's tracer counts too"
    assert helper_count(2 * MIN_CELLS_PER_PART - 1, settings, cores=2, memory=lots) == 0, "a small grid: no helper"
    assert helper_count(580, RTSettings(batch_independent=False), cores=2, memory=lots) == 0
    assert helper_count(580, settings, cores=2, memory=None) == 1, "unknown memory: by cores and cells"


# ------------------------------------------------------------------------------------------- real ray tracer
@pytest.fixture()
def room(tmp_path, tiny_room):
    """The tiny room's free cells, traced in batches of one cell (so that the parts alternate between processes)."""
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.scenes import load_scene_spec

    path = tmp_path / "room.toml"
    path.write_text(tiny_room)
    spec = load_scene_spec(str(path), "blueprint")
    iy, ix = np.nonzero(~occupancy(spec))
    xs, ys = spec.grid.centres()
    points = np.stack([xs[ix], ys[iy], np.full(len(ix), spec.rx_height_m)], axis=1)
    settings = RTSettings(max_depth=2, samples_per_src=2_000, device="cpu", batch_size=1)
    return spec, settings, points, ix, iy


@pytest.fixture()
def small_parts(monkeypatch):
    """Parts of one cell: the tiny room's few cells are shared with the helper."""
    monkeypatch.setattr(trace_helpers, "MIN_CELLS_PER_PART", 1)


def _in_one_call(room):
    from dtradar_data.pipeline.batches import trace_batch
    from dtradar_data.rt.tracer import RayTracer

    spec, settings, points, ix, iy = room
    tracer = RayTracer(spec, settings)
    return tracer, trace_batch(tracer, points, ix, iy, per_path=True)


def _joined(results) -> tuple[dict, dict]:
    cells = {k: np.concatenate([c[k] for _, (c, _) in results]) for k in results[0][1][0] if k != "retrace_depth"}
    paths = {k: np.concatenate([p[k] for _, (_, p) in results]) for k in results[0][1][1]}
    return cells, paths


def _assert_same(joined, whole) -> None:
    cells, paths = joined
    for k, v in cells.items():
        np.testing.assert_array_equal(v, whole[0][k], err_msg=k)
    for k, v in paths.items():
        np.testing.assert_array_equal(v, whole[1][k], err_msg=k)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
@pytest.mark.sionna
def test_cells_a_helper_traces_are_the_bytes_this_process_traces(room, small_parts):
    from dtradar_data.pipeline.trace_helpers import TraceHelpers

    spec, settings, points, ix, iy = room
    tracer, whole = _in_one_call(room)
    with TraceHelpers(1, spec, settings) as helpers:
        assert helpers.splits(len(points), settings)
        results = helpers.trace(tracer, spec, settings, points, ix, iy, per_path=True)
        assert [sl.stop - sl.start for sl, _ in results] == [1] * len(points), "one cell per part, alternating"
        _assert_same(_joined(results), whole)
        assert helpers.count == 1
    tracer.close()


@pytest.mark.sionna
def test_an_error_in_a_helper_is_raised_in_the_build(room, small_parts):
    from dtradar_data.core.errors import InvalidCoordinatesError
    from dtradar_data.pipeline.trace_helpers import TraceHelpers

    spec, settings, points, ix, iy = room
    tracer, _ = _in_one_call(room)
    outside = points.copy()
    outside[1::2, 0] = 1e6  # the parts the helper gets (every second cell) lie outside the room
    with TraceHelpers(1, spec, settings) as helpers, pytest.raises(InvalidCoordinatesError):
        helpers.trace(tracer, spec, settings, outside, ix, iy, per_path=True)
    tracer.close()


@pytest.mark.sionna
def test_a_helper_that_dies_leaves_its_cells_to_this_process(room, small_parts, capsys):
    from dtradar_data.pipeline.trace_helpers import TraceHelpers

    spec, settings, points, ix, iy = room
    tracer, whole = _in_one_call(room)
    with TraceHelpers(1, spec, settings) as helpers:
        (helper,) = helpers._helpers
        helper.proc.kill()
        helper.proc.wait()
        results = helpers.trace(tracer, spec, settings, points, ix, iy, per_path=True)
        _assert_same(_joined(results), whole)
        assert helpers.count == 0 and not helpers.splits(len(points), settings)
    assert "this process traces its cells from now on" in capsys.readouterr().err
    tracer.close()
