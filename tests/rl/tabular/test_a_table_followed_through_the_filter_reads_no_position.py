"""A learnt table followed through the localisation filter (FilterTablePolicy): it acts on honest observations only,
reaches its targets on the blueprint, re-plans around what it senses, and a target without a column has no vote."""

import numpy as np
import torch

from dtradar_rl.agents.radio_filter import FilterConfig
from dtradar_rl.evaluation.evaluate import evaluate, sample_eval_pairs
from dtradar_rl.experiments.offline_tabular import grid_table
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.tabular.batch import BatchConfig, empirical_model, learn
from dtradar_rl.tabular.filter_table import FilterTablePolicy
from dtradar_rl.tabular.solver import TabularMDP
from dtradar_rl.task.sensing import honest_dim
from dtradar_rl.task.twins import load_dataset


def _policy(replan: bool):
    bp = load_dataset("synthetic-8x6/blueprint")
    logged = log_dataset(
        LogConfig(
            scene="synthetic-8x6", behaviour="random", steps=2000, num_envs=16, seed=1, minari=False, verbose=False
        )
    )
    tab = TabularMDP.from_dataset(bp)
    model = empirical_model(logged, tab)
    targets = np.unique(sample_eval_pairs(bp, 40, 2024)[:, 1])
    table = learn("ce", model, targets, BatchConfig())
    cfg = FilterConfig(scene="synthetic-8x6", noise="none")
    return bp, FilterTablePolicy(
        bp, grid_table(tab, table), targets, "CE", cfg, replan=("ce", model, BatchConfig()) if replan else None
    )


def test_the_policy_observes_the_honest_preset_and_reaches_its_targets(root):
    bp, policy = _policy(replan=True)
    assert policy.obs_preset == "honest" and policy.meta["localise"] == "filter"
    metrics, _ = evaluate(policy, bp, pairs=40, latency=False)
    assert metrics.success_rate >= 0.9


def test_two_robots_on_different_cells_that_sense_the_same_act_the_same(root):
    # the policy holds no env and its observation is the honest one: what it does cannot depend on where it stands
    bp, policy = _policy(replan=False)
    env = policy.env_for(bp, 2)
    pairs = sample_eval_pairs(bp, 40, 2024)
    pairs = pairs[[0, int(np.flatnonzero(pairs[:, 0] != pairs[0, 0])[0])]]  # two robots on different cells
    env.reset_where(torch.ones(2, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    obs = env.observe()
    assert obs.shape[1] == honest_dim(bp.transmitters)
    a = policy.act(obs[:1].expand(2, -1).clone())
    assert a[0] == a[1]


def test_a_target_without_a_column_has_no_vote(root):
    bp, policy = _policy(replan=False)
    policy._start(1)
    policy._col = torch.tensor([-1])
    votes = policy._votes(torch.full((1, bp.shape[0] * bp.shape[1]), 1.0 / (bp.shape[0] * bp.shape[1])))
    assert torch.equal(votes, torch.zeros(1, 4))


def test_on_a_changed_twin_it_replans_around_what_it_senses(root):
    dynamic = load_dataset("synthetic-8x6/dynamic")
    _, plain = _policy(replan=False)
    _, replanning = _policy(replan=True)
    before, _ = evaluate(plain, dynamic, pairs=40, latency=False)
    after, _ = evaluate(replanning, dynamic, pairs=40, latency=False)
    assert replanning.meta["stats"].get("replans", 0) > 0
    assert after.spl >= before.spl
