"""Physics and determinism of the ray tracer on a tiny scene: a floor slab, a few receivers (needs Sionna)."""

from dataclasses import replace

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_data.core.grid import Grid
from dtradar_data.scenes.model import Box, SceneSpec, TxSpec

pytestmark = pytest.mark.sionna

C = 299_792_458.0
F = 2.4e9
TX = (0.3, -0.2, 3.0)  # off the floor mesh diagonal x = y: a reflection point exactly on a triangle edge is missed


def tiny_spec() -> SceneSpec:
    floor = Box(
        name="floor",
        kind="floor",
        material="concrete",
        x_m=0.0,
        y_m=0.0,
        width_m=20.0,
        length_m=20.0,
        height_m=0.1,
        z_m=-0.1,
    )
    return SceneSpec(
        scene="tiny",
        variant="blueprint",
        title="tiny",
        description="a floor slab",
        source="test",
        licence="CC0-1.0",
        attribution="test",
        grid=Grid(x0_m=1.0, y0_m=1.0, cell_m=1.0, nx=3, ny=2),
        tx=TxSpec(position_m=TX, num_rows=1, num_cols=1, pattern="iso", polarization="V"),
        rx_height_m=1.0,
        robot_height_m=1.0,
        objects=(floor,),
    )


@pytest.fixture(scope="module")
def iso_settings():
    from dtradar_data.rt.settings import RTSettings

    return RTSettings(
        rx_pattern="iso", rx_polarization="V", max_depth=2, samples_per_src=200_000, device="cpu", batch_size=4
    )


@pytest.fixture(scope="module")
def traced(iso_settings):
    from dtradar_data.pipeline.tracing import trace_grid

    cells, paths, blocked, tracer = trace_grid(tiny_spec(), iso_settings, progress=False)
    tracer.close()
    return cells, paths


def test_the_line_of_sight_path_has_the_geometric_delay_angles_and_friis_gain(traced):
    cells, paths = traced
    los = paths.filter(paths.column("interactions").to_numpy(zero_copy_only=False) == "").to_pydict()
    assert len(los["ix"]) == 6, "every receiver sees the transmitter"
    for k in range(6):
        x, y = 1.0 + los["ix"][k], 1.0 + los["iy"][k]
        d = np.array([x - TX[0], y - TX[1], 1.0 - TX[2]])
        r = np.linalg.norm(d)
        assert los["tau_s"][k] == pytest.approx(r / C, rel=1e-5)
        friis_db = 20 * np.log10(C / F / (4 * np.pi * r))
        assert abs(los["power_db"][k] - friis_db) < 1.0
        assert los["aod_zen_rad"][k] == pytest.approx(np.arccos(d[2] / r), abs=np.deg2rad(0.1))
        assert los["aod_az_rad"][k] == pytest.approx(np.arctan2(d[1], d[0]), abs=np.deg2rad(0.1))
        assert los["aoa_zen_rad"][k] == pytest.approx(np.arccos(-d[2] / r), abs=np.deg2rad(0.1))
        assert los["aoa_az_rad"][k] == pytest.approx(np.arctan2(-d[1], -d[0]), abs=np.deg2rad(0.1))


def test_the_floor_reflection_is_found_and_the_los_path_is_the_strongest(traced):
    cells, paths = traced
    assert all(cells.column("los").to_pylist())
    assert min(cells.column("num_paths").to_pylist()) >= 2
    assert "S" in paths.column("interactions").to_pylist()
    # strongest-path delay is the LoS delay
    tau = np.array(cells.column("tau_s").to_pylist())
    x, y = np.array(cells.column("x_m").to_pylist()), np.array(cells.column("y_m").to_pylist())
    r = np.sqrt((x - TX[0]) ** 2 + (y - TX[1]) ** 2 + (1.0 - TX[2]) ** 2)
    np.testing.assert_allclose(tau, r / C, rtol=1e-5)


def test_the_same_scene_and_seed_give_identical_tables(traced, iso_settings):
    from dtradar_data.pipeline.tracing import trace_grid

    cells, paths, _, tracer = trace_grid(tiny_spec(), iso_settings, progress=False)
    tracer.close()
    assert cells.equals(traced[0]) and paths.equals(traced[1])


def test_an_interrupted_trace_resumes_from_its_finished_batches(tmp_path, traced, iso_settings):
    from dtradar_data.pipeline.batches import batch_dir
    from dtradar_data.pipeline.tracing import trace_grid

    settings = replace(iso_settings, batch_size=2)  # 3 batches for 6 cells
    first, _, _, tracer = trace_grid(tiny_spec(), settings, tmp_path, progress=False)
    tracer.close()
    where = batch_dir(tmp_path, settings, 2)
    assert sorted(p.name for p in where.iterdir()) == ["batch_00000.npz", "batch_00001.npz", "batch_00002.npz"]
    (where / "batch_00001.npz").unlink()  # as if interrupted while tracing batch 1
    stamp = (where / "batch_00000.npz").stat().st_mtime_ns
    again, _, _, tracer = trace_grid(tiny_spec(), settings, tmp_path, progress=False)
    tracer.close()
    assert again.equals(first)
    assert (where / "batch_00000.npz").stat().st_mtime_ns == stamp, "finished batches are reused, not redone"


def test_receivers_outside_the_scene_are_rejected_before_tracing(iso_settings):
    from dtradar_data.rt.tracer import RayTracer

    tracer = RayTracer(tiny_spec(), iso_settings)
    try:
        with pytest.raises(InvalidCoordinatesError, match="outside the scene"):
            tracer.trace(np.array([[0.0, 0.0, 1.0], [500.0, 0.0, 1.0]]))
        with pytest.raises(InvalidCoordinatesError, match="NaN"):
            tracer.trace(np.array([[np.nan, 0.0, 1.0]]))
    finally:
        tracer.close()


def test_per_cell_features_follow_the_contract_on_the_paper_arrays():
    from dtradar_data.core.schema import CELL_SCHEMA
    from dtradar_data.pipeline.tracing import trace_grid
    from dtradar_data.rt.settings import RTSettings

    settings = RTSettings(max_depth=2, samples_per_src=5_000, device="cpu")  # -> vertical dipole
    paper_tx = TxSpec(position_m=TX, look_at_m=(1.0, 1.0, 0.0))  # 8x2 tr38901 VH, the paper's array
    cells, paths, _, tracer = trace_grid(replace(tiny_spec(), tx=paper_tx), settings, progress=False)
    tracer.close()
    assert cells.schema.equals(CELL_SCHEMA)
    a = np.array(cells.column("a_re").to_pylist()) + 1j * np.array(cells.column("a_im").to_pylist())
    np.testing.assert_allclose(np.angle(a), cells.column("phase_rad").to_pylist(), atol=1e-5)
    spread = np.array(cells.column("delay_spread_s").to_pylist())
    two = np.array(cells.column("num_paths").to_pylist()) >= 2
    assert two.any() and (spread[two] > 0).all() and (spread[~two] == 0).all()
