"""How a grid is cut into trace calls: Sionna's solver keeps the batch size it is given (it is part of the version);
batch-independent tracing makes the calls even, and a build resumed with another ``--rt.batch-size`` (the same
version) keeps its batch files apart instead of reading one of another size as its own."""

from dataclasses import replace

import numpy as np
import pytest

from dtradar_data.pipeline.batches import batch_dir, batch_layout, load_batch
from dtradar_data.rt.settings import RTSettings


def test_sionnas_solver_keeps_the_batch_size_it_is_given():
    stock = RTSettings(batch_size=1024, batch_independent=False)  # the engine of the versions built before
    assert batch_layout(1950, stock) == 1024
    assert batch_layout(10, stock) == 1024


@pytest.mark.parametrize(
    ("cells", "size", "expected"), [(1950, 1024, 975), (1950, 256, 244), (592, 128, 119), (10, 1024, 10), (7, 7, 7)]
)
def test_batch_independent_calls_are_as_few_as_the_batch_size_allows_and_even(cells, size, expected):
    settings = RTSettings(batch_size=size, batch_independent=True)
    got = batch_layout(cells, settings)
    assert got == expected
    assert got <= size
    calls = -(-cells // got)
    assert calls == -(-cells // size), "no more calls than the batch size needs"
    assert cells - (calls - 1) * got >= got - calls, "the last call is about as big as the others"


def test_batch_files_of_each_layout_go_to_their_own_folder_only_when_batch_independent(tmp_path):
    stock = RTSettings(batch_size=5, batch_independent=False)
    assert batch_dir(tmp_path, stock, 5) == tmp_path
    independent = replace(stock, batch_independent=True)
    assert batch_dir(tmp_path, independent, 5) != batch_dir(tmp_path, independent, 7)
    assert batch_dir(tmp_path, independent, 5).parent == tmp_path


@pytest.mark.sionna
def test_a_batch_independent_build_resumed_with_another_batch_size_gets_the_same_table(tmp_path):
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.pipeline.tracing import trace_grid
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("cubicle", "blueprint")
    spec = replace(spec, grid=replace(spec.grid, nx=6, ny=4))
    free = int((~occupancy(spec)).sum())
    settings = RTSettings(max_depth=1, samples_per_src=2_000, batch_size=5, device="cpu", batch_independent=True)
    first, *_ = trace_grid(spec, settings, tmp_path, per_path=False, progress=False)
    kept = sorted(batch_dir(tmp_path, settings, batch_layout(free, settings)).glob("batch_*.npz"))
    assert len(kept) > 1
    kept[-1].unlink()  # an interrupted build: its last batch missing
    resumed, *_ = trace_grid(spec, replace(settings, batch_size=7), tmp_path, per_path=False, progress=False)
    assert resumed.equals(first)
    fives = sorted(batch_dir(tmp_path, settings, batch_layout(free, settings)).glob("batch_*.npz"))
    assert fives == kept[:-1], "the other layout's files are left alone, not read as this one's"
    sizes = [len(load_batch(p)[0]["num_paths"]) for p in fives]
    assert set(sizes) == {batch_layout(free, settings)} and np.sum(sizes) < free


def _batch(n: int, p: int, with_paths: int = 0):
    from dtradar_data.rt.tracer import PathBatch

    valid = np.zeros((n, p), bool)
    valid[:with_paths, :p] = True
    f = np.ones((n, p))
    return PathBatch(
        valid, f.astype(np.complex64), f * 1e-9, f * 1e-8, f, f, f, f, np.zeros((2, n, p), np.uint32), 2.4e9
    )


def test_a_batch_independent_call_in_which_no_receiver_has_a_path_reduces_to_empty_rows():
    from dtradar_data.pipeline.batches import _reduce_cells
    from dtradar_data.rt import features

    empty = _reduce_cells(_batch(3, 0))  # Sionna returns zero path slots when no receiver of the call has one
    assert set(empty) == set(features.reduce_cells(_batch(3, 0))) and all(len(v) == 3 for v in empty.values())
    assert (empty["num_paths"] == 0).all()
    some = _reduce_cells(_batch(3, 2, with_paths=1))
    assert list(some["num_paths"]) == [2, 0, 0]
