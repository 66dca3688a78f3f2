"""The clock (``clock="sincos"``): the schedule's phase as the cell part's last two columns, after every fixed
column (the ring's included); ``"none"`` is the table byte for byte; on a static twin the phase is constant and the
width is a moving twin's; an unknown clock is a typed error."""

import numpy as np
import pytest

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.task.clock import CLOCKS, clock_columns
from dtradar_rl.task.observations import Normalizer, build_observations, obs_dim
from dtradar_rl.task.twins import load_dataset


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def test_no_clock_is_the_table_byte_for_byte(moving):
    norm = Normalizer.fit(moving)
    plain = build_observations(moving, "neighbors", norm, sense_radius=3)
    none = build_observations(moving, "neighbors", norm, sense_radius=3, clock="none")
    assert plain.cell_part.tobytes() == none.cell_part.tobytes() and plain.names == none.names
    assert CLOCKS == ("none", "sincos") and clock_columns("none") == 0


@pytest.mark.parametrize("preset,radius", [("goal", 1), ("neighbors", 1), ("neighbors", 3)])
def test_the_phase_comes_last_in_the_cell_part_and_moves_no_column(moving, preset, radius):
    norm = Normalizer.fit(moving)
    plain = build_observations(moving, preset, norm, sense_radius=radius)
    timed = build_observations(moving, preset, norm, sense_radius=radius, clock="sincos")
    dc = plain.cell_part.shape[1]
    assert timed.cell_part[:, :dc].tobytes() == plain.cell_part.tobytes()
    assert timed.ring_columns == plain.ring_columns
    assert timed.names == plain.names[:dc] + ("clock_cos", "clock_sin") + plain.names[dc:]
    assert timed.dim == plain.dim + 2 == obs_dim(preset, 1, radius, "sincos")
    t_count, cells = moving.snapshots, plain.target_part.shape[0]
    for t in range(t_count):
        rows = timed.cell_part[timed.row(np.arange(cells), t), dc:]
        angle = 2 * np.pi * t / t_count
        np.testing.assert_allclose(rows, np.tile([np.cos(angle), np.sin(angle)], (cells, 1)), atol=1e-6)


def test_on_a_static_twin_the_phase_is_constant_and_the_width_is_the_moving_twins(moving):
    ds = load_dataset("synthetic-12x8/blueprint")
    table = build_observations(ds, "neighbors", Normalizer.fit(ds), sense_radius=2, clock="sincos")
    np.testing.assert_array_equal(table.cell_part[:, -2:], np.tile([1.0, 0.0], (table.cell_part.shape[0], 1)))
    moving_table = build_observations(moving, "neighbors", Normalizer.fit(moving), sense_radius=2, clock="sincos")
    assert table.dim == moving_table.dim


def test_an_unknown_clock_is_a_typed_error(moving):
    with pytest.raises(UnknownNameError, match="clock"):
        build_observations(moving, "goal", Normalizer.fit(moving), clock="onehot")
