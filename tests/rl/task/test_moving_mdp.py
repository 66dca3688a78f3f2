"""The MDP in time: the moving twin format, snapshot stepping, wall and mover collisions, mover hits, the periodic
wrap, and what the robot observes at its snapshot."""

import numpy as np
import pyarrow as pa
import pytest

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidCoordinatesError, SchemaMismatchError
from dtradar_data.pipeline.synthetic import Mover, synthetic_moving_dataset
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP
from dtradar_rl.task.moving_masks import background, moving_masks
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.twins import load_dataset

X_MINUS, X_PLUS, Y_MINUS, Y_PLUS = range(4)


@pytest.fixture(scope="module")
def moving():
    return load_dataset("synthetic-moving-12x8/blueprint")


def lane(positions) -> MovingGridMDP:
    """A 4 x 1 lane, one mover at ``positions[t]`` (a cell index, or None) in snapshot t."""
    blocked = np.zeros((len(positions), 1, 4), bool)
    for t, p in enumerate(positions):
        if p is not None:
            blocked[t, 0, p] = True
    return MovingGridMDP.from_masks(blocked, name="lane")


# -- the format ---------------------------------------------------------------------------------------------------
def test_the_synthetic_moving_twin_follows_the_format(moving):
    h, w = moving.shape
    t_count = moving.snapshots
    assert moving.is_moving and t_count == moving.meta["moving"]["snapshots"] == 6
    assert moving.meta["moving"]["movers"] == ["walker-0", "walker-1", "walker-2"]
    assert moving.table.num_rows == t_count * h * w
    t = moving.table.column("t").to_numpy()
    assert moving.table.schema.field("t").type == pa.int32() and (np.diff(t) >= 0).all()
    blocked, mover = moving_masks(moving)
    assert (mover.sum(1) >= 1).all() and not (mover & ~blocked).any()
    static = load_dataset("synthetic-12x8/blueprint")
    assert ((blocked & ~mover) == static.blocked.ravel()).all()  # the static obstacles, in every snapshot
    # radio features: the static twin's, null where a mover is
    snap = moving.snapshot(5)
    gain, gain0 = snap.grid(["a_re"])[..., 0].ravel(), static.grid(["a_re"])[..., 0].ravel()
    assert np.isnan(gain[mover[5]]).all()
    free = ~blocked[5]
    np.testing.assert_array_equal(gain[free], gain0[free])
    assert snap.meta["snapshot"] == {"t": 5, "time_s": 5.0} and "moving" not in snap.meta


def test_a_static_twin_is_one_snapshot_and_a_moving_one_refuses_a_single_grid(moving):
    static = load_dataset("synthetic-12x8/blueprint")
    assert not static.is_moving and static.snapshots == 1 and static.snapshot(0) is static
    with pytest.raises(SchemaMismatchError, match="moving twin of 6 snapshots"):
        _ = moving.blocked
    with pytest.raises(SchemaMismatchError, match="ds.snapshot"):
        moving.grid(["a_re"])
    with pytest.raises(InvalidCoordinatesError, match="snapshot 6"):
        moving.snapshot(6)


def test_from_table_sorts_a_moving_table_by_snapshot_then_cell(moving):
    shuffled = moving.table.take(np.random.default_rng(0).permutation(moving.table.num_rows))
    again = Dataset.from_table(shuffled, moving.meta, name=moving.name)
    assert again.table.equals(moving.table)


def test_a_table_that_breaks_the_format_is_refused(moving):
    table = moving.table
    mover = table.column("mover").to_numpy().copy()
    blocked = table.column("blocked").to_numpy()
    mover[np.flatnonzero(~blocked)[0]] = True  # a mover on a free cell
    bad = table.set_column(table.schema.get_field_index("mover"), "mover", pa.array(mover))
    with pytest.raises(SchemaMismatchError, match="has a mover but is not blocked"):
        GridMDP.from_dataset(Dataset(moving.name, bad, moving.meta))
    blocked2 = blocked.copy()
    blocked2[np.flatnonzero(~blocked)[-1]] = True  # a static obstacle that appears in one snapshot
    bad = table.set_column(table.schema.get_field_index("blocked"), "blocked", pa.array(blocked2))
    with pytest.raises(SchemaMismatchError, match="static obstacles"):
        GridMDP.from_dataset(Dataset(moving.name, bad, moving.meta))
    no_meta = {k: v for k, v in moving.meta.items() if k != "moving"}
    with pytest.raises(SchemaMismatchError, match="needs both"):
        _ = Dataset(moving.name, table, no_meta).snapshots


def test_synthetic_movers_walk_back_and_forth_and_loop():
    m = Mover("m", (1, 2), "x", 3)
    assert [m.cell(k) for k in range(6)] == [(1, 2), (2, 2), (3, 2), (2, 2), (1, 2), (2, 2)]
    assert m.period == 4 and Mover("still", (0, 0), "y", 1).cell(7) == (0, 0)
    ds = synthetic_moving_dataset(5, 3, movers=[m], blocked=None)
    assert ds.snapshots == 4
    with pytest.raises(InvalidCoordinatesError, match="on an obstacle"):
        synthetic_moving_dataset(5, 3, movers=[m], blocked=np.eye(3, 5, 2, dtype=bool)[::-1])


# -- the MDP ------------------------------------------------------------------------------------------------------
def test_the_mdp_of_a_moving_twin_is_its_static_map_plus_what_moves(moving):
    mdp = GridMDP.from_dataset(moving)
    assert isinstance(mdp, MovingGridMDP) and mdp.snapshots == 6 and mdp.movers == ("walker-0", "walker-1", "walker-2")
    blocked, mover = moving_masks(moving)
    np.testing.assert_array_equal(mdp.covered, blocked)
    np.testing.assert_array_equal(mdp.blocked.ravel(), blocked.all(0))  # walls: blocked in every snapshot
    np.testing.assert_array_equal(mdp.blocked_at(7), blocked[1].reshape(mdp.blocked.shape))
    assert not background(moving).is_moving
    np.testing.assert_array_equal(background(moving).blocked, mdp.blocked)


def test_a_wall_is_a_collision_as_on_a_static_twin():
    mdp = lane([None, None])
    assert mdp.step_at(0, 0, X_MINUS) == (0, 1, True, False, False)  # off the grid
    assert mdp.step_at(3, 1, X_PLUS) == (3, 0, True, False, False)


def test_a_move_into_a_cell_a_mover_covers_at_the_next_snapshot_is_a_mover_collision():
    mdp = lane([3, 1, 3])  # the mover is on cell 1 at snapshot 1 only
    assert mdp.step_at(0, 0, X_PLUS) == (0, 1, False, True, False)  # stays
    assert mdp.step_at(0, 1, X_PLUS) == (1, 2, False, False, False)  # gone by snapshot 2: the move succeeds
    # the mover's cell *now* does not matter when it leaves it (no one comes the other way)
    assert mdp.step_at(2, 1, X_MINUS) == (1, 2, False, False, False)


def test_passing_through_a_mover_coming_the_other_way_is_a_mover_collision_and_a_hit():
    mdp = lane([2, 1, 0, 1])  # walks 2 -> 1 -> 0 -> 1
    # robot on 0 at snapshot 1 moves X+ into 1 while the mover moves 1 -> 0: they would swap
    assert mdp.step_at(0, 1, X_PLUS) == (0, 2, False, True, True)


def test_a_mover_walking_onto_a_robot_that_stays_is_a_mover_hit():
    mdp = lane([2, 1, 0, 1])
    # robot on 0 bumps the wall at snapshot 1; the mover arrives on 0 at snapshot 2: the robot is not pushed
    cell, t, wall, mover_collision, hit = mdp.step_at(0, 1, X_MINUS)
    assert (cell, t, wall, mover_collision, hit) == (0, 2, True, False, True)
    # sharing the cell, the robot can move out; the mover leaves it too
    assert mdp.step_at(0, 2, X_PLUS) == (0, 3, False, True, False)  # the mover is on 1 at snapshot 3
    assert mdp.step_at(0, 3, X_MINUS) == (0, 0, True, False, False)  # wrap: snapshot 0, the mover on 2


def test_snapshots_wrap_after_the_last():
    mdp = lane([3, 2, 1])
    assert mdp.step_at(0, 2, X_PLUS)[1] == 0
    assert mdp.step_at(0, 2, X_MINUS)[:2] == (0, 0)
    assert mdp.step_at(2, 2, X_PLUS) == (2, 0, False, True, False)  # snapshot 0 again: the mover on 3
    assert mdp.step_at(2, 5, X_PLUS) == mdp.step_at(2, 2, X_PLUS)  # t is taken mod T


def test_the_gymnasium_env_steps_through_snapshots_with_periodic_wrap(moving):
    env = DtradarNavEnv(moving, obs="neighbors", max_steps=50)
    mdp = env.mdp
    (s, t, t0) = (int(v) for v in mdp.sample_episodes(1, np.random.default_rng(1))[0])
    _, info = env.reset(options={"start": mdp.xy(s), "target": mdp.xy(t), "t0": t0})
    assert info["t"] == t0
    for n in range(1, 30):
        _, _, term, _, info = env.step(n % 4)
        assert info["t"] == (t0 + n) % mdp.snapshots
        if term:
            break


def test_the_robot_observes_its_cell_and_neighbours_at_its_snapshot(moving):
    norm = Normalizer.fit(moving)
    table = build_observations(moving, "neighbors", norm)
    mdp = GridMDP.from_dataset(moving)
    n = mdp.num_cells
    assert table.snapshots == 6 and table.cell_part.shape[0] == 6 * n
    flags = [table.names.index(f"{a}:has_radio") for a in ("X-", "X+", "Y-", "Y+")]
    for t in range(mdp.snapshots):  # each snapshot's rows are that snapshot's static table
        snap = build_observations(moving.snapshot(t), "neighbors", norm)
        np.testing.assert_array_equal(table.cell_part[t * n : (t + 1) * n], snap.cell_part)
    # a free cell next to a mover reads that neighbour as blocked in that snapshot and as free in another
    t, m = (int(v) for v in np.argwhere(mdp.mover)[0])
    c = next(int(c) for c in range(n) if not mdp.covered[t, c] and m in mdp.next_cell[c] and c != m)
    a = int(np.flatnonzero(mdp.next_cell[c] == m)[0])
    assert table.observe(c, c, t)[flags[a]] == 0
    t_free = int(np.flatnonzero(~mdp.covered[:, m])[0])
    assert table.observe(c, c, t_free)[flags[a]] == 1
    # the target's part does not change when a mover covers the target
    target_xy = table.observe(c, m, t)[-2:]
    assert np.abs(target_xy).sum() > 0


def test_the_normaliser_of_a_moving_twin_uses_the_free_cells_of_every_snapshot(moving):
    norm = Normalizer.fit(moving)
    values = np.concatenate([moving.snapshot(k).grid(["a_re"])[..., 0].ravel() for k in range(moving.snapshots)])
    assert norm.mean[norm.columns.index("a_re")] == pytest.approx(float(np.nanmean(values.astype(np.float64))))
