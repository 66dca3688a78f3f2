"""A cell's rows do not depend on the batch it is traced in: the same cells traced inside two different batches give
the same per-cell and per-path bytes, also when the candidate hash table collides a lot and when the path buffer
fills (the batch is then re-traced in halves). Real ray tracer on corners of the cubicle (needs Sionna)."""

import numpy as np
import pytest

pytestmark = pytest.mark.sionna


@pytest.fixture(scope="module")
def cubicle():
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("cubicle", "blueprint")
    blocked = occupancy(spec)
    xs, ys = spec.grid.centres()
    iy, ix = np.nonzero(~blocked)
    points = np.stack([xs[ix], ys[iy], np.full(len(ix), spec.rx_height_m)], axis=1)
    return spec, points, ix, iy


def settings(**kw):
    from dtradar_data.rt.settings import RTSettings

    return RTSettings(max_depth=3, samples_per_src=3_000, device="cpu", batch_independent=True, **kw)


def traced(tracer, points, ix, iy, cells):
    """Trace ``cells`` (positions among ``points``) as one batch; their per-cell and per-path arrays."""
    from dtradar_data.pipeline.batches import trace_batch

    return trace_batch(tracer, points[cells], ix[cells], iy[cells], per_path=True)


def cell_bytes(result, k: int) -> dict[str, bytes]:
    """The radio features of the batch's ``k``-th cell, as bytes (not how it was traced: ``retrace_depth``)."""
    cells, _ = result
    return {f"cell.{name}": np.asarray(v[k]).tobytes() for name, v in cells.items() if name != "retrace_depth"}


def path_bytes(result, cell_ix: int, cell_iy: int) -> dict[str, bytes]:
    """The per-path rows of one cell, as bytes."""
    _, paths = result
    mine = (paths["ix"] == cell_ix) & (paths["iy"] == cell_iy)
    return {f"path.{name}": as_bytes(np.asarray(v[mine])) for name, v in paths.items()}


def as_bytes(x: np.ndarray) -> bytes:
    """The array's bytes; an object array (the interaction letters) as its strings' bytes."""
    return "\n".join(map(str, x)).encode() if x.dtype == object else x.tobytes()


def assert_same_rows(a, b, cells_a, cells_b, ix, iy):
    """Each cell traced in batch ``a`` at position ``cells_a.index(c)`` and in ``b`` has the same bytes."""
    for c in sorted(set(cells_a) & set(cells_b)):
        ka, kb = list(cells_a).index(c), list(cells_b).index(c)
        assert cell_bytes(a, ka) == cell_bytes(b, kb), f"cell {c}: per-cell row differs"
        assert path_bytes(a, ix[c], iy[c]) == path_bytes(b, ix[c], iy[c]), f"cell {c}: per-path rows differ"


def test_cells_traced_inside_two_different_batches_have_the_same_bytes(cubicle):
    from dtradar_data.rt.tracer import RayTracer

    spec, points, ix, iy = cubicle
    tracer = RayTracer(spec, settings())
    try:
        n = len(points)
        shared = list(range(0, n, n // 10))[:10]  # ten cells spread over the room
        others = [c for c in range(n) if c not in shared][::7][:30]
        one = traced(tracer, points, ix, iy, shared)  # the ten alone
        mixed = others[:15] + shared[::-1] + others[15:]  # among thirty others, in another order and place
        two = traced(tracer, points, ix, iy, mixed)
        assert (one[0]["num_paths"] > 0).all()
        assert_same_rows(one, two, shared, mixed, ix, iy)
        assert tracer.overflowed_calls == 0
    finally:
        tracer.close()


def test_cells_keep_their_bytes_when_the_hash_table_collides_a_lot(cubicle, monkeypatch):
    """With 64 slots per receiver most chains collide; the collisions are each receiver's own, so rows still agree."""
    from dtradar_data.rt.tracer import RayTracer

    spec, points, ix, iy = cubicle
    tracer = RayTracer(spec, settings())
    # the solver's module imports Sionna, so only once the tracer has; its loop reads the slot count at each call
    import dtradar_data.rt.batch_independent_solver as solver_module

    monkeypatch.setattr(solver_module, "HASH_SLOTS_PER_RX", 64)
    try:
        cells = list(range(3, 40, 4))
        a = traced(tracer, points, ix, iy, cells)
        b = traced(tracer, points, ix, iy, list(range(0, 40)))
        assert_same_rows(a, b, cells, list(range(0, 40)), ix, iy)
    finally:
        tracer.close()


def test_a_batch_that_fills_the_path_buffer_is_re_traced_in_halves_with_the_same_bytes(cubicle):
    from dtradar_data.rt.tracer import RayTracer

    spec, points, ix, iy = cubicle
    tracer = RayTracer(spec, settings(max_num_paths_per_src=400))
    try:
        cells = list(range(8))
        alone = [traced(tracer, points, ix, iy, [c]) for c in cells]
        assert tracer.overflowed_calls == 0, "one cell must fit the buffer for this test"
        together = traced(tracer, points, ix, iy, cells)
        assert tracer.overflowed_calls > 0
        assert (together[0]["retrace_depth"] > 0).all()
        for c in cells:
            assert_same_rows(alone[c], together, [c], cells, ix, iy)
    finally:
        tracer.close()


def test_with_batch_independence_the_batch_size_leaves_the_version_and_without_it_stays():
    from dtradar_data.rt.settings import BATCH_INDEPENDENT_ENGINE, RTSettings

    stock = RTSettings(batch_independent=False).hashed()
    assert "batch_independent" not in stock and stock["batch_size"] == 1024  # stored versions keep their hashes
    a, b = RTSettings(batch_size=64), RTSettings(batch_independent=True, batch_size=1024)  # the default is on
    assert a.hashed() == b.hashed() and "batch_size" not in a.hashed()
    assert a.hashed()["batch_independent"] == BATCH_INDEPENDENT_ENGINE
    assert a.hashed() != {**stock, "batch_independent": BATCH_INDEPENDENT_ENGINE}  # not a stock version's hash
