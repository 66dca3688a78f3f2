"""TablePolicy: a table over blueprint cells that acts by fingerprint localisation and lookup."""

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.evaluation.evaluate import evaluate, evaluate_twins, rollout
from dtradar_rl.tabular.fingerprints import localisation
from dtradar_rl.tabular.table_policy import TablePolicy, UncoveredTargetError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset


@pytest.fixture(scope="module")
def twins():
    return load_dataset("synthetic-12x8/blueprint"), load_dataset("synthetic-12x8/dynamic")


def shortest_table(ds) -> np.ndarray:
    """``int64[cells, cells]``: a breadth-first shortest move from every cell to every target of ``ds``."""
    mdp = GridMDP.from_dataset(ds)
    dist = mdp.bfs_distances_many(np.arange(mdp.num_cells)).astype(np.float64)  # [target, cell]
    dist[dist < 0] = np.inf
    ahead = dist[:, mdp.next_cell]  # [target, cell, 4]
    ahead[:, mdp.collides] = np.inf
    return ahead.argmin(-1).T.astype(np.int64)  # [cell, target]


def every_pair(ds):
    mdp = GridMDP.from_dataset(ds)
    free = np.flatnonzero(mdp.free)
    cells, targets = np.meshgrid(free, free, indexing="ij")
    return cells.ravel(), targets.ravel()


def test_a_table_policy_acts_as_its_table_says_at_the_cell_localisation_believes(twins):
    bp, dyn = twins
    n = bp.shape[0] * bp.shape[1]
    table = np.random.default_rng(0).integers(0, 4, (n, n))
    policy = TablePolicy(bp, table)
    for ds in (bp, dyn):
        cells, targets = every_pair(ds)
        obs = torch.as_tensor(policy.observations(ds).observe(cells, targets))
        believed = localisation(bp, ds)[cells]
        assert torch.equal(policy.act(obs), torch.as_tensor(table[believed, targets]))
    # the oracle reads the true cell from the observation's own position
    cells, targets = every_pair(dyn)
    obs = torch.as_tensor(policy.observations(dyn).observe(cells, targets))
    assert torch.equal(policy.oracle().act(obs), torch.as_tensor(table[cells, targets]))


def test_the_shortest_move_table_runs_through_the_evaluation_loop_on_both_twins(twins):
    bp, dyn = twins
    policy = TablePolicy(bp, shortest_table(bp), name="shortest")
    metrics, _ = evaluate(policy, bp, pairs=100, latency=False)
    assert metrics.success_rate == 1.0 and metrics.spl == pytest.approx(1.0) and metrics.collisions == 0
    rows = evaluate_twins(
        policy,
        "synthetic-12x8",
        ["blueprint", "dynamic"],
        pairs=50,
        datasets={bp.name: bp, dyn.name: dyn},
        latency=False,
    )
    assert [r["dataset"] for r, _, _ in rows] == [bp.name, dyn.name]  # the goal preset: no shielded rows
    # with the dynamic twin's own table and the true cell it never fails there
    oracle = TablePolicy(bp, shortest_table(dyn)).oracle()
    assert evaluate(oracle, dyn, pairs=100, latency=False)[0].success_rate == 1.0


def test_a_probability_table_draws_its_moves_repeatably_and_a_one_hot_one_acts_like_the_moves(twins):
    bp, _ = twins
    moves = shortest_table(bp)
    one_hot = np.eye(4)[moves]
    pairs = GridMDP.from_dataset(bp).sample_pairs(40, np.random.default_rng(1))
    a = rollout(TablePolicy(bp, moves), bp, pairs)
    b = rollout(TablePolicy(bp, one_hot), bp, pairs)
    assert a.paths == b.paths
    uniform = TablePolicy(bp, np.full(moves.shape + (4,), 0.25))
    assert rollout(uniform, bp, pairs).paths == rollout(uniform, bp, pairs).paths  # env_for restarts the draws


def test_a_table_over_some_targets_refuses_a_target_it_has_no_column_for(twins):
    bp, _ = twins
    n = bp.shape[0] * bp.shape[1]
    free = np.flatnonzero(GridMDP.from_dataset(bp).free)
    policy = TablePolicy(bp, np.zeros((n, 3), np.int64), targets=free[:3])
    obs = torch.as_tensor(policy.observations(bp).observe(free[3:5], free[[0, 7]]))
    with pytest.raises(UncoveredTargetError, match="no column"):
        policy.act(obs)


@pytest.mark.parametrize(
    "table", [np.zeros((5, 5), np.int64), np.full((96, 96), 4), np.zeros((96, 96)), np.full((96, 96, 4), 0.3)]
)
def test_a_table_of_the_wrong_shape_or_values_is_refused(twins, table):
    with pytest.raises(InvalidSettingError):
        TablePolicy(twins[0], table)
