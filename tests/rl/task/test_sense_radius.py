"""Wider sensing (``sense_radius``): radius 1 is the ``neighbors`` table unchanged; a radius R appends the has-radio
flags of the cells at Manhattan distance 2..R, in the robot's snapshot and in the one before (periodic at t = 0),
equal to a brute-force reading of the twin; a bad radius is a typed error."""

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.task.observations import (
    OBS_DIMS,
    RADIO_FEATURES,
    Normalizer,
    build_observations,
    ring_cells,
    ring_offsets,
)
from dtradar_rl.task.twins import load_dataset

RADIUS = 3


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def brute_force_flag(ds, t: int, ix: int, iy: int) -> float:
    """1 where cell ``(ix, iy)`` of snapshot ``t`` is on the grid, free and has every radio feature, read from the
    snapshot's own table."""
    snap = ds.snapshot(t) if ds.is_moving else ds
    ny, nx = snap.shape
    if not (0 <= ix < nx and 0 <= iy < ny):
        return 0.0
    radio = snap.grid(list(RADIO_FEATURES))[iy, ix]
    return float(not np.asarray(snap.blocked, bool)[iy, ix] and np.isfinite(radio).all())


def test_radius_one_is_the_neighbors_table_byte_for_byte(moving):
    norm = Normalizer.fit(moving)
    plain = build_observations(moving, "neighbors", norm)
    one = build_observations(moving, "neighbors", norm, sense_radius=1)
    assert plain.sense_radius == one.sense_radius == 1 and plain.names == one.names
    assert plain.cell_part.tobytes() == one.cell_part.tobytes()
    assert plain.dim == OBS_DIMS["neighbors"] and plain.ring_columns == slice(46, 46)
    wide = build_observations(moving, "neighbors", norm, sense_radius=RADIUS)
    # the neighbors columns keep their place (and values); the ring sits between them and the target
    assert wide.cell_part[:, :46].tobytes() == plain.cell_part.tobytes()
    assert wide.names[:46] == plain.names[:46] and wide.names[-2:] == plain.names[-2:]
    assert np.array_equal(wide.target_part, plain.target_part)
    k = 2 * RADIUS * (RADIUS + 1) - 4
    assert wide.dim == plain.dim + 2 * k and wide.ring_columns == slice(46, 46 + 2 * k)


def test_the_ring_holds_every_cell_at_distance_two_to_r_once():
    off = ring_offsets(RADIUS)
    dist = np.abs(off).sum(1)
    assert len({tuple(o) for o in off.tolist()}) == len(off) == 2 * RADIUS * (RADIUS + 1) - 4
    assert dist.min() == 2 and dist.max() == RADIUS and (np.diff(dist) >= 0).all()
    assert len(ring_offsets(1)) == 0
    cells = ring_cells(5, 4, 2)  # a corner sees 3 of its 8 ring cells, the rest is off the grid
    assert (cells[0] >= 0).sum() == 3


@pytest.mark.parametrize("t", [0, 1, 5])
def test_the_ring_flags_equal_a_brute_force_reading_now_and_a_snapshot_before(moving, t):
    table = build_observations(moving, "neighbors", Normalizer.fit(moving), sense_radius=RADIUS)
    ny, nx = moving.shape
    before = (t - 1) % moving.snapshots  # t = 0: the periodic world's last snapshot
    for cell in range(nx * ny):
        iy, ix = divmod(cell, nx)
        obs = table.observe(cell, 0, t)
        for dx, dy in ring_offsets(RADIUS).tolist():
            assert obs[table.names.index(f"has_radio[{dx:+d},{dy:+d}]")] == brute_force_flag(
                moving, t, ix + dx, iy + dy
            ), (cell, dx, dy)
            assert obs[table.names.index(f"has_radio_before[{dx:+d},{dy:+d}]")] == brute_force_flag(
                moving, before, ix + dx, iy + dy
            ), (cell, dx, dy)
    # the two frames differ somewhere: a mover walked
    ring = table.cell_part[table.row(np.arange(nx * ny), t)][:, table.ring_columns]
    k = ring.shape[1] // 2
    assert (ring[:, :k] != ring[:, k:]).any()


def test_on_a_static_twin_the_frame_before_is_the_static_map():
    ds = load_dataset("synthetic-12x8/dynamic")
    table = build_observations(ds, "neighbors", Normalizer.fit(ds), sense_radius=RADIUS)
    ring = table.cell_part[:, table.ring_columns]
    k = ring.shape[1] // 2
    assert np.array_equal(ring[:, :k], ring[:, k:]) and 0 < ring.mean() < 1
    iy, ix = divmod(40, ds.shape[1])
    for dx, dy in ring_offsets(RADIUS).tolist():
        assert table.observe(40, 0)[table.names.index(f"has_radio[{dx:+d},{dy:+d}]")] == brute_force_flag(
            ds, 0, ix + dx, iy + dy
        )


@pytest.mark.parametrize("bad", [0, -2, 1.5, True, "2", None])
def test_a_bad_sense_radius_is_a_typed_error(moving, bad):
    with pytest.raises(InvalidSettingError, match="sense radius must be an integer >= 1"):
        build_observations(moving, "neighbors", Normalizer.fit(moving), sense_radius=bad)


@pytest.mark.parametrize("preset", ["paper", "goal"])
def test_a_wider_radius_needs_the_neighbors_preset(moving, preset):
    with pytest.raises(InvalidSettingError, match="'neighbors'"):
        build_observations(moving, preset, Normalizer.fit(moving), sense_radius=2)
    assert build_observations(moving, preset, Normalizer.fit(moving), sense_radius=1).sense_radius == 1
