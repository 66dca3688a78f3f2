"""The fingerprint planner on a twin with two transmitters: it localises by every transmitter's features and plans
through the streets only the second one hears, which a one-transmitter twin shows as walls."""

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer


def _every_target(ds):
    mdp = GridMDP.from_dataset(ds)
    cells = mdp.pair_cells()
    rng = np.random.default_rng(0)  # every target, from three random starts each
    return np.array(
        [(s, t) for t in cells for s in rng.choice([c for c in cells if c != t and mdp.connected(c, t)], 3)]
    )


def test_the_planner_localises_by_every_transmitter_and_reaches_streets_only_the_second_one_hears(tx_twin):
    two, one = tx_twin(silent=False), tx_twin(silent=False, k=1)
    planner = FingerprintPlanner(two)
    table = planner.observations(two)
    assert planner.fingerprints.shape[1] == 16
    assert torch.equal(planner.cells, torch.as_tensor(np.flatnonzero(table.has_radio)))
    assert planner.cells.numel() == int(GridMDP.from_dataset(two).free.sum())  # every free cell hears someone
    m = metrics_from_rollouts(rollout(planner, two, _every_target(two)))
    assert m.success_rate == 1.0 and m.spl == pytest.approx(1.0) and m.collisions == 0
    # transmitter 0 alone: the right third is silent, read as walls, and the planner gets lost there
    alone = metrics_from_rollouts(rollout(FingerprintPlanner(one), one, _every_target(one)))
    assert alone.success_rate < 0.9


def test_a_planner_of_two_transmitters_is_refused_on_a_twin_with_one(tx_twin):
    two, one = tx_twin(), tx_twin(k=1)
    with pytest.raises(InvalidSettingError, match="2 transmitter"):
        FingerprintPlanner(one, Normalizer.fit(two))
