"""Exact values agree with rollouts: a table policy's exact value equals the discounted return the benchmark's
rollouts measure (the true-value column), a memoryless policy's greedy table is read back through its own act(),
and the return-based normalised score puts uniform moves at 0 and the optimum at 100. A tiny synthetic twin."""

import numpy as np
import pytest

from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.evaluation.returns import pair_values, return_references, return_score
from dtradar_rl.offline.ope import true_value
from dtradar_rl.tabular.evaluation import greedy_table, policy_values
from dtradar_rl.tabular.solver import TabularMDP, solve
from dtradar_rl.tabular.table_policy import TablePolicy
from dtradar_rl.task.twins import load_dataset

TWIN = "synthetic-12x8/blueprint"


@pytest.fixture()
def twin():
    return load_dataset(TWIN)


def random_table(tab: TabularMDP, targets: np.ndarray, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 4, (targets.size, tab.n))


def as_grid(tab: TabularMDP, table: np.ndarray) -> np.ndarray:
    full = np.zeros((tab.mdp.num_cells, table.shape[0]), np.int64)
    full[tab.cells] = table.T
    return full


@pytest.mark.parametrize("reward", ["geodesic", "paper"])
def test_a_table_policys_exact_value_is_what_its_rollouts_return(twin, reward):
    tab = TabularMDP.from_dataset(twin)
    pairs = sample_eval_pairs(twin, 60, 5)
    targets = np.unique(pairs[:, 1])
    sol = solve(tab, reward, 0.9, targets)
    for table in (sol.greedy(), random_table(tab, targets)):
        policy = TablePolicy(twin, as_grid(tab, table), targets=targets, localise="oracle")
        exact = pair_values(tab, policy_values(tab, table, targets, reward, 0.9), targets, pairs).mean()
        rolled = true_value(policy, twin, pairs, gamma=0.9, reward=reward, max_steps=400)
        assert rolled == pytest.approx(exact, rel=1e-6, abs=1e-6)


def test_a_memoryless_policys_greedy_table_is_read_through_its_own_act(twin):
    tab = TabularMDP.from_dataset(twin)
    targets = tab.cells[::7]
    table = random_table(tab, targets, seed=3)
    policy = TablePolicy(twin, as_grid(tab, table), targets=targets, localise="oracle")
    np.testing.assert_array_equal(greedy_table(policy, twin, tab, targets), table)


def test_the_return_score_is_0_for_uniform_moves_and_100_for_the_optimum(twin):
    refs = return_references(twin, pairs=80, seed=2)
    assert return_score(refs["random"], refs) == 0 and return_score(refs["optimal"], refs) == 100
    assert refs["optimal"] > refs["random"]


def test_following_a_localised_table_gives_the_episodes_of_its_rollout_on_another_twin():
    from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout
    from dtradar_rl.experiments.offline_tabular import localised_table
    from dtradar_rl.tabular.evaluation import follow, path_metrics
    from dtradar_rl.tabular.fingerprints import localisation

    blueprint, dynamic = load_dataset(TWIN), load_dataset("synthetic-12x8/dynamic")
    tab_bp, tab = TabularMDP.from_dataset(blueprint), TabularMDP.from_dataset(dynamic)
    pairs = sample_eval_pairs(dynamic, 80, 4)
    targets = np.unique(pairs[:, 1])
    table = solve(tab_bp, "geodesic", 0.9, targets).greedy()  # the blueprint's optimum, blind to the new obstacles
    policy = TablePolicy(blueprint, as_grid(tab_bp, table), targets=targets)
    seen = localised_table(tab_bp, tab, localisation(blueprint, dynamic), table)
    followed = path_metrics(follow(tab, seen, np.searchsorted(targets, pairs[:, 1]), pairs[:, 0], pairs[:, 1], 400))
    rolled = metrics_from_rollouts(rollout(policy, dynamic, pairs, max_steps=400)).to_dict()
    for key in ("success_rate", "spl", "collisions"):
        assert followed[key] == pytest.approx(rolled[key], abs=1e-12), key
    assert followed["success_rate"] < 1.0  # the test means something: the dynamic twin's obstacles stop some
