"""Tabular batch RL from a logged dataset: the empirical model counts what was logged and nothing else, the data
ceiling bounds every policy that stays inside the data, full coverage lets every learner reach the optimum, and a log
that contradicts its twin is refused, as is one of another scene or grid (a typed error naming both, not an
IndexError). Tiny synthetic twins."""

import numpy as np
import pytest

from dtradar_data.core.errors import CorruptDatasetError, InvalidSettingError
from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.tabular.batch import BatchConfig, EmpiricalModel, ceiling, empirical_model, learn
from dtradar_rl.tabular.evaluation import follow, path_metrics, policy_values
from dtradar_rl.tabular.solver import TabularMDP, solve
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset

SCENE = "synthetic-10x6"
CFG = LogConfig(scene=SCENE, behaviour="random", steps=6000, num_envs=16, seed=0, minari=False, verbose=False)


@pytest.fixture()
def logged(root):
    return log_dataset(CFG)


@pytest.fixture()
def tab():
    return TabularMDP.from_dataset(load_dataset(f"{SCENE}/blueprint"))


def test_the_empirical_model_counts_every_logged_step_and_sees_the_twins_moves(logged, tab):
    m = empirical_model(logged, tab)
    assert m.counts.sum() == len(logged)
    seen = m.seen
    assert (m.successor[seen] == tab.next[seen]).all() and (m.counts[seen] > 0).all()
    np.testing.assert_allclose(m.behaviour.sum(1), 1.0)


def test_full_coverage_lets_every_learner_reach_the_optimum(logged, tab):
    m = empirical_model(logged, tab)
    ok = np.isin(tab.cells, tab.mdp.pair_cells())  # not the single cells walled in on their own: nobody goes there
    assert m.seen[ok].all()  # 6 000 random steps see every move of the others
    pairs = sample_eval_pairs(load_dataset(f"{SCENE}/blueprint"), 100, 3)
    targets = np.unique(pairs[:, 1])
    star = solve(tab, m.reward, 0.9, targets)
    for name in ("ce", "lcb"):
        a = learn(name, m, targets, BatchConfig(lcb_beta=0.0))
        np.testing.assert_allclose(policy_values(tab, a, targets, m.reward)[:, ok], star.values[:, ok], rtol=1e-9)
    probs = learn("spibb", m, targets, BatchConfig(spibb_n_wedge=1))
    np.testing.assert_allclose(policy_values(tab, probs, targets, m.reward)[:, ok], star.values[:, ok], rtol=1e-6)
    assert ceiling(m, pairs)["spl"] == 1.0


def test_the_ceiling_bounds_every_policy_that_uses_only_logged_moves(logged, tab):
    full = empirical_model(logged, tab)
    rng = np.random.default_rng(0)
    drop = rng.random(full.counts.shape) < 0.3  # forget 30 % of the moves
    m = EmpiricalModel(tab, np.where(drop, 0, full.counts), np.where(drop, -1, full.successor), full.reward)
    pairs = sample_eval_pairs(load_dataset(f"{SCENE}/blueprint"), 200, 1)
    targets = np.unique(pairs[:, 1])
    rows = np.searchsorted(targets, pairs[:, 1])
    c = ceiling(m, pairs)
    assert c["spl"] < 1.0
    a = learn("lcb", m, targets, BatchConfig(lcb_beta=0.0))
    has = m.seen.any(1)
    assert m.seen[np.arange(tab.n)[None], a][:, has].all()  # it never leaves the data where it can stay in it
    got = path_metrics(follow(tab, a, rows, pairs[:, 0], pairs[:, 1], tab.mdp.max_steps))
    assert got["spl"] <= c["spl"] + 1e-12
    v = policy_values(tab, a, targets, m.reward)
    np.testing.assert_allclose(v, c["values"], rtol=1e-9)  # the greedy restricted policy is worth the ceiling


def test_a_log_that_contradicts_its_twin_is_refused(logged, tab):
    other = TabularMDP.from_dataset(load_dataset(f"{SCENE}/dynamic"))  # the dynamic twin blocks cells it visits
    with pytest.raises(CorruptDatasetError):
        empirical_model(logged, other)


@pytest.mark.parametrize("other", ["synthetic-8x6", "synthetic-12x8"])  # a smaller grid, a larger one
def test_a_log_of_another_scene_is_refused_naming_both(logged, other):
    tab = TabularMDP.from_dataset(load_dataset(f"{other}/blueprint"))  # the smaller used to be an IndexError
    with pytest.raises(InvalidSettingError, match=f"{SCENE}/blueprint/random.*{other}/blueprint") as e:
        empirical_model(logged, tab)
    assert f"--scene {other}" in str(e.value)


def test_a_log_beyond_a_hand_made_twins_grid_is_refused_naming_both(logged):
    tab = TabularMDP.from_mdp(GridMDP.from_blocked(np.zeros((6, 8), bool)))  # no scene name to compare: the grid
    with pytest.raises(InvalidSettingError, match=f"{SCENE}/blueprint/random.*grid.*8 x 6"):
        empirical_model(logged, tab)


def test_bad_settings_are_refused():
    for bad in (dict(lcb_beta=-1.0), dict(lcb_beta=float("nan")), dict(spibb_n_wedge=0), dict(gamma=1.0)):
        with pytest.raises(InvalidSettingError):
            BatchConfig(**bad).validate()
    with pytest.raises(Exception, match="did you mean|one of"):
        learn("cee", None, np.array([0]))
