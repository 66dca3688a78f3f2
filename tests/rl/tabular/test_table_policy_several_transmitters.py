"""Table policies on a twin with two transmitters: fingerprints hold every transmitter's features, so the believed
cell is the true one wherever any transmitter is heard, and the observation's columns are read the same way."""

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.tabular.fingerprints import fingerprints, localisation
from dtradar_rl.tabular.table_policy import TablePolicy
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer


def shortest_table(ds) -> np.ndarray:
    """``int64[cells, cells]``: a breadth-first shortest move from every cell to every target (as test_table_policy)."""
    mdp = GridMDP.from_dataset(ds)
    dist = mdp.bfs_distances_many(np.arange(mdp.num_cells)).astype(np.float64)  # [target, cell]
    dist[dist < 0] = np.inf
    ahead = dist[:, mdp.next_cell]  # [target, cell, 4]
    ahead[:, mdp.collides] = np.inf
    return ahead.argmin(-1).T.astype(np.int64)  # [cell, target]


def every_pair(ds):
    free = np.flatnonzero(GridMDP.from_dataset(ds).free)
    cells, targets = np.meshgrid(free, free, indexing="ij")
    return cells.ravel(), targets.ravel()


def test_fingerprints_of_two_transmitters_locate_every_cell_either_one_hears(two_tx):
    norm = Normalizer.fit(two_tx)
    fp, radio = fingerprints(two_tx, norm)
    table = TablePolicy(two_tx, shortest_table(two_tx), normalizer=norm).observations(two_tx)
    assert fp.shape[1] == 16
    np.testing.assert_array_equal(radio, table.has_radio)
    loc = localisation(two_tx)
    heard = np.flatnonzero(radio)
    np.testing.assert_array_equal(loc[heard], heard)


def test_a_table_policy_believes_what_localisation_says_on_a_twin_with_two_transmitters(two_tx):
    policy = TablePolicy(two_tx, shortest_table(two_tx))
    table = policy.observations(two_tx)
    cells, targets = every_pair(two_tx)
    believed, seen = policy.localiser(table.observe(cells, targets))
    np.testing.assert_array_equal(believed, localisation(two_tx)[cells])
    np.testing.assert_array_equal(seen, targets)
    assert policy.localiser.hears(table.observe(cells, targets)).tolist() == table.has_radio[cells].tolist()


def test_the_shortest_move_table_reaches_every_target_when_every_cell_hears_a_transmitter(tx_twin):
    ds = tx_twin(silent=False)
    metrics, _ = evaluate(TablePolicy(ds, shortest_table(ds)), ds, pairs=100)
    assert metrics.success_rate == 1.0
    assert GridMDP.from_dataset(ds).free.sum() == fingerprints(ds, Normalizer.fit(ds))[1].sum()


def test_a_table_of_two_transmitters_is_refused_on_a_twin_with_one(two_tx, tx_twin):
    one = tx_twin(k=1)
    with pytest.raises(InvalidSettingError, match="observes 2 transmitter"):
        localisation(two_tx, one)
