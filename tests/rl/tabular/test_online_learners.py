"""Tabular Q-learning and Dyna-Q online against the table: they learn, Dyna faster, and their settings are checked."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.tabular import dyna, qlearning
from dtradar_rl.tabular.table_policy import TablePolicy, TooLargeError, check_table_size, greedy_actions
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset

TINY = "synthetic-12x8"


@pytest.fixture(scope="module")
def tiny():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    ds = load_dataset(f"{TINY}/blueprint")
    yield ds, sample_eval_pairs(ds, 100, 2024)
    torch.set_num_threads(before)


def success(policy, ds, pairs) -> float:
    return metrics_from_rollouts(rollout(policy, ds, pairs)).success_rate


def steps_to_reach(learn, cfg, ds, pairs, level: float, every: int = 1024) -> int | None:
    """The first env step count at which the greedy table reaches ``level`` success (checked every ``every``)."""
    seen: dict[str, int] = {}

    def callback(q, env_steps, _train_s):
        if env_steps - seen.get("last", -every) >= every:
            seen["last"] = env_steps
            if success(TablePolicy(ds, greedy_actions(q)), ds, pairs) >= level:
                seen["reached"] = env_steps
                return True
        return False

    learn(cfg, ds, callback=callback)
    return seen.get("reached")


def test_q_learning_on_a_tiny_grid_reaches_the_target_from_most_pairs(tiny):
    ds, pairs = tiny
    cfg = qlearning.QLearningConfig(scene=TINY, total_env_steps=60_000, save=False, verbose=False, threads=1)
    result = qlearning.learn(cfg, ds)
    assert result.env_steps >= 60_000 and result.episodes > 1000
    assert success(result.policy, ds, pairs) >= 0.9


def test_dyna_reaches_the_target_in_fewer_env_steps_than_q_learning(tiny):
    ds, pairs = tiny
    common = dict(scene=TINY, total_env_steps=60_000, save=False, verbose=False, threads=1)
    q_steps = steps_to_reach(qlearning.learn, qlearning.QLearningConfig(**common), ds, pairs, 0.9)
    d_steps = steps_to_reach(dyna.learn, dyna.DynaConfig(**common), ds, pairs, 0.9)
    assert d_steps is not None and q_steps is not None
    assert d_steps * 4 <= q_steps  # measured (seeds 0-2): 1 280 against 28 928-38 144


def test_dyna_with_hindsight_learns_every_target_from_the_moves_it_has_tried(tiny):
    ds, _ = tiny
    cfg = dyna.DynaConfig(scene=TINY, total_env_steps=10_240, planning_steps=0, save=False, verbose=False, threads=1)
    result = dyna.learn(cfg, ds)
    free = np.flatnonzero(~np.asarray(ds.blocked, bool).ravel())
    assert result.stats["model_entries"] == 4 * free.size  # every move of every free cell tried
    # each target's column was updated, not only the targets the robots had
    touched = (result.q[free][:, free] != 0).any(-1)  # [cell, target]
    assert touched.sum() >= 0.9 * free.size * (free.size - 1)


def test_a_table_too_large_for_the_memory_cap_is_refused_before_it_is_allocated(tiny):
    ds, _ = tiny
    cfg = qlearning.QLearningConfig(scene=TINY, max_table_gib=1e-4, save=False, verbose=False)
    with pytest.raises(TooLargeError, match=r"96 cells x 96 targets x 4 actions = 0\.00 GiB, over the cap"):
        qlearning.learn(cfg, ds)
    with pytest.raises(TooLargeError, match=r"30,000 cells x 30,000 targets x 4 actions = 13\.41 GiB"):
        check_table_size(30_000, 30_000, 2 << 30)


@pytest.mark.parametrize(
    "cls, setting",
    [
        (qlearning.QLearningConfig, {"gamma": 1.0}),
        (qlearning.QLearningConfig, {"gamma": -0.1}),
        (qlearning.QLearningConfig, {"lr": 0.0}),
        (qlearning.QLearningConfig, {"lr": 1.5}),
        (qlearning.QLearningConfig, {"lr_end": 0.0}),
        (qlearning.QLearningConfig, {"eps_start": 1.5}),
        (qlearning.QLearningConfig, {"eps_decay_fraction": -0.1}),
        (qlearning.QLearningConfig, {"num_envs": 0}),
        (qlearning.QLearningConfig, {"total_env_steps": 0}),
        (qlearning.QLearningConfig, {"max_table_gib": 0.0}),
        (qlearning.QLearningConfig, {"gamma": float("nan")}),
        (qlearning.QLearningConfig, {"num_envs": 2.5}),
        (dyna.DynaConfig, {"planning_steps": -1}),
        (dyna.DynaConfig, {"planning_batch": 0}),
        (dyna.DynaConfig, {"planning_targets": -3}),
    ],
)
def test_config_validation_rejects_a_bad_value_naming_its_flag(cls, setting):
    flag = "--" + next(iter(setting)).replace("_", "-")
    with pytest.raises(ConfigError, match=flag):
        cls(**setting)


def test_an_unknown_reward_is_refused_when_the_config_is_validated():
    with pytest.raises(UnknownNameError):
        qlearning.QLearningConfig(reward="nope").validate()


def test_a_run_saves_its_config_as_json_and_a_table_policy_that_loads_back(tiny, tmp_path):
    ds, pairs = tiny
    cfg = dyna.DynaConfig(scene=TINY, total_env_steps=5_000, out=str(tmp_path / "run"), verbose=False, threads=1)
    result = dyna.learn(cfg, ds)
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved.pop("learner") == "dyna" and dyna.DynaConfig.from_dict(saved) == cfg
    record = json.loads((tmp_path / "run" / "result.json").read_text())
    assert record["stats"]["env_steps"] == result.env_steps and record["dataset"]["name"] == ds.name
    loaded = TablePolicy.load(tmp_path / "run", ds)
    assert torch.equal(loaded.table, result.policy.table)
    assert rollout(loaded, ds, pairs).paths == rollout(result.policy, ds, pairs).paths


def blanked(ds, cells):
    """``ds`` with no radio features on ``cells`` (free cells no propagation path reaches)."""
    import pyarrow as pa

    from dtradar_data.core.dataset import Dataset
    from dtradar_rl.task.observations import RADIO_FEATURES

    table = ds.table
    rows = np.isin(np.arange(table.num_rows), cells)
    for name in RADIO_FEATURES:
        column = table.column(name).to_numpy(zero_copy_only=False).astype(np.float64)
        values = pa.array(np.where(rows, np.nan, column), mask=rows, type=table.schema.field(name).type)
        table = table.set_column(table.schema.get_field_index(name), name, values)
    return Dataset.from_table(table, ds.meta, name=ds.name)


def test_cells_without_radio_features_do_not_corrupt_the_row_of_the_cell_their_blank_fingerprint_matches():
    from dtradar_rl.tabular.fingerprints import localisation
    from dtradar_rl.task.grid_mdp import GridMDP

    torch.set_num_threads(1)
    base = load_dataset("synthetic-16x10/blueprint")
    mdp = GridMDP.from_dataset(base)
    corner = [c for c in np.flatnonzero(mdp.free) if mdp.xy(c)[0] <= 1 and mdp.xy(c)[1] <= 2]
    ds = blanked(base, corner)
    believed = localisation(ds)[corner]
    assert len(set(believed.tolist())) == 1 and believed[0] not in corner  # they all match one other cell
    cfg = dyna.DynaConfig(scene="synthetic-16x10", total_env_steps=20_480, save=False, verbose=False, threads=1)
    result = dyna.learn(cfg, ds)
    # from the matched cell itself the table finds the way to every target a robot reaches from a cell where it
    # senses radio features (two corner targets lie behind blank cells: no fingerprint says where the robot is there)
    heard = mdp.free & ~np.isin(np.arange(mdp.num_cells), corner)
    ok = [t for t in np.flatnonzero(mdp.free) if t != believed[0] and heard[mdp.next_cell[t]].any()]
    assert len(ok) == mdp.free.sum() - 3
    pairs = np.array([(believed[0], t) for t in ok])
    assert metrics_from_rollouts(rollout(result.policy.oracle(), ds, pairs)).success_rate == 1.0
