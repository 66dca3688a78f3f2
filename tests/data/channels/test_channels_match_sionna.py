"""Channels generated from the stored per-path table match Sionna's own ``Paths.cfr()`` for other arrays (needs
Sionna): a tiny room (floor, a concrete wall, a wooden box: reflections and refractions) traced once with
``--rt.path-channels`` at the paper's arrays, then traced again by a plain ``sionna.rt.PathSolver`` with the arrays
of a study at the same receivers."""

from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from dtradar_data.core.grid import Grid
from dtradar_data.scenes.model import Box, SceneSpec, TxSpec

pytestmark = pytest.mark.sionna

FREQS = np.arange(-32, 32) * 120e3  # 64 subcarriers, 7.68 MHz around the carrier


def room() -> SceneSpec:
    def box(name, kind, material, x, y, w, length, h, z=0.0):
        return Box(name=name, kind=kind, material=material, x_m=x, y_m=y, width_m=w, length_m=length, height_m=h, z_m=z)

    return SceneSpec(
        scene="channel-room",
        variant="blueprint",
        title="channel room",
        description="a floor, a wall and a box",
        source="test",
        licence="CC0-1.0",
        attribution="test",
        grid=Grid(x0_m=0.5, y0_m=0.5, cell_m=1.0, nx=3, ny=2),
        tx=TxSpec(
            position_m=(0.3, -0.7, 2.5),
            num_rows=2,
            num_cols=2,
            pattern="tr38901",
            polarization="VH",
            look_at_m=(1.5, 1.0, 0.0),
        ),
        rx_height_m=1.0,
        robot_height_m=1.0,
        objects=(
            box("floor", "floor", "concrete", 1.5, 1.0, 8.0, 8.0, 0.1, -0.1),
            box("wall", "wall", "concrete", 4.2, 1.0, 0.2, 6.0, 3.0),
            box("crate", "obstacle", "wood", 1.5, 3.2, 1.0, 0.4, 1.5),
        ),
    )


@pytest.fixture(scope="module")
def stored():
    """The room traced with the channel columns (Sionna's own solver, so that a plain PathSolver finds the same
    paths), as a dataset with its per-path table, and the tracer (its scene is re-used for the reference)."""
    from dtradar_data.core.dataset import Dataset
    from dtradar_data.pipeline.tracing import _receivers, trace_grid
    from dtradar_data.rt.settings import RTSettings

    spec = room()
    settings = RTSettings(
        max_depth=3, samples_per_src=20_000, device="cpu", batch_independent=False, path_channels=True
    )
    cells, paths, _, tracer = trace_grid(spec, settings, progress=False)
    meta = {"rt": settings.hashed(), "transmitter": spec.tx.to_dict()}
    yield Dataset(name="channel-room", table=cells, meta=meta, paths_table=paths), tracer, _receivers(spec), settings
    tracer.close()


def sionna_cfr(tracer, points, settings, tx, rx, tx_orientation, rx_orientation):
    """Sionna's own frequency response ``[N, rx ports, tx ports, F]``: a plain PathSolver on the same scene with the
    study's arrays, one thread as the dataset's trace (its multi-threaded collection changes the weak paths)."""
    import drjit as dr

    scene, rt = tracer.scene, tracer.rt
    scene.tx_array, scene.rx_array = tx.sionna(), rx.sionna()
    scene.get("tx").orientation = list(tx_orientation)
    tracer._set_receivers(points)
    for name in tracer._rx_names:
        scene.get(name).orientation = list(rx_orientation)
    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        paths = rt.PathSolver()(scene, **settings.solver_kwargs())
    finally:
        dr.set_thread_count(threads)
    return np.asarray(paths.cfr(frequencies=FREQS, out_type="numpy"))[:, :, 0, :, 0, :]


def nmse_db(h, ref):
    err = np.sum(np.abs(h - ref) ** 2, axis=(1, 2, 3)) / np.sum(np.abs(ref) ** 2, axis=(1, 2, 3))
    return 10 * np.log10(err)


@pytest.mark.parametrize(
    "tx, rx, tx_orientation, rx_orientation",
    [
        # the paper's kind of link, one element each: a TR 38.901 element at the dataset's pose, a vertical dipole
        (("1x1", 1, 1, "tr38901", "V"), ("1x1", 1, 1, "dipole", "V"), None, (0.0, 0.0, 0.0)),
        # a 4 x 4 cross-polarised UPA turned away from the dataset's pose, a 2-element dual-polarised receiver
        (("4x4", 4, 4, "tr38901", "cross"), ("1x2", 1, 2, "dipole", "VH"), (0.3, -0.2, 0.1), (0.4, 0.2, -0.3)),
    ],
    ids=["single-element-pair", "4x4-upa-to-2-elements"],
)
def test_generated_frequency_responses_match_sionnas_own_to_minus_40_db(stored, tx, rx, tx_orientation, rx_orientation):
    from dtradar_data.channels import Array, ChannelGenerator

    dataset, tracer, receivers, settings = stored
    tx, rx = Array(*tx[1:]), Array(*rx[1:])
    gen = ChannelGenerator(
        dataset, tx, rx, frequencies_hz=FREQS, tx_orientation=tx_orientation, rx_orientation=rx_orientation
    )
    out = gen.generate(np.stack([receivers.ix, receivers.iy], axis=1))
    ref = sionna_cfr(tracer, receivers.points, settings, tx, rx, gen.tx_orientation, rx_orientation)
    assert out.h.shape == ref.shape == (len(receivers.points), rx.num_ports, tx.num_ports, len(FREQS))
    assert out.num_paths.min() >= 3, "reflections and refractions, not only the line of sight"
    assert nmse_db(out.h, ref).max() <= -40.0


def test_the_impulse_response_sums_to_the_frequency_response_and_cells_come_in_the_order_asked(stored):
    from dtradar_data.channels import Array, ChannelGenerator

    dataset, _, receivers, _ = stored
    gen = ChannelGenerator(dataset, Array(2, 2, "tr38901", "VH"), Array(), frequencies_hz=FREQS)
    cells = np.stack([receivers.ix, receivers.iy], axis=1)[::-1]
    out = gen.generate(cells)
    assert (out.ix == cells[:, 0]).all() and (out.iy == cells[:, 1]).all()
    valid = out.tau_s >= 0
    assert (valid.sum(axis=1) == out.num_paths).all() and (out.tau_s.min(axis=1, where=valid, initial=1) == 0).all()
    h = np.einsum("crtp,cpf->crtf", out.a, np.exp(-2j * np.pi * np.where(valid, out.tau_s, 0)[..., None] * FREQS))
    np.testing.assert_allclose(h, out.h, rtol=0, atol=1e-6 * np.abs(out.h).max())
    batches = list(gen.batches(cells, batch_cells=4))
    assert [len(b.ix) for b in batches] == [4, 2]
    np.testing.assert_array_equal(np.concatenate([b.h[:, :, :, :] for b in batches[:1]]), out.h[:4, :, :, :])


def test_storing_the_channel_columns_leaves_every_other_column_unchanged(stored):
    from dtradar_data.core.schema import CHANNEL_PATH_COLUMNS, PATH_COLUMNS
    from dtradar_data.pipeline.tracing import trace_grid

    dataset, _, _, settings = stored
    cells, paths, _, tracer = trace_grid(room(), replace(settings, path_channels=False), progress=False)
    tracer.close()
    assert cells.equals(dataset.table)
    assert paths.equals(dataset.paths_table.select(list(PATH_COLUMNS)).cast(paths.schema))
    assert dataset.paths_table.column_names == [*PATH_COLUMNS, *CHANNEL_PATH_COLUMNS]
    depth = dataset.paths_table.column("depth").to_numpy()
    lengths = pa.compute.list_value_length(dataset.paths_table.column("vertices_m")).to_numpy()
    assert (lengths == 3 * depth).all(), "x, y, z of every interaction"
