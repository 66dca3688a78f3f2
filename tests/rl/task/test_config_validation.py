"""Every config checks its numbers when it is made (a wrong type, NaN or infinity, a negative step count, a learning
rate <= 0, a probability outside [0, 1]) and names the --flag; lists that name runs refuse repeats and unknown
scenes before anything runs; on the command line each is one `error:` line, exit 2, nothing written."""

import dataclasses

import pytest

from dtradar_data.core.errors import DatasetNotFoundError, InvalidSettingError, UnknownNameError
from dtradar_rl.cli import main
from dtradar_rl.evaluation.jobs import CrossConfig, EvalConfig
from dtradar_rl.experiments.adapt import AdaptConfig
from dtradar_rl.experiments.sweep import SweepConfig
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.task.config import ConfigError, deferred_checks
from dtradar_rl.train.config import DQNConfig

BAD = [
    (DQNConfig, {"max_steps": -1}, "--max-steps"),
    (DQNConfig, {"total_env_steps": -5}, "--total-env-steps"),
    (DQNConfig, {"total_env_steps": 1000.5}, "--total-env-steps"),
    (DQNConfig, {"num_envs": True}, "--num-envs"),
    (DQNConfig, {"seed": -1}, "--seed"),
    (DQNConfig, {"lr": 0.0}, "--lr"),
    (DQNConfig, {"lr": float("nan")}, "--lr"),
    (DQNConfig, {"lr_end": float("nan")}, "--lr-end"),
    (DQNConfig, {"max_grad_norm": float("nan")}, "--max-grad-norm"),
    (DQNConfig, {"expert_weight": float("inf")}, "--expert-weight"),
    (DQNConfig, {"eps_start": 1.5}, "--eps-start"),
    (DQNConfig, {"eps_end": -0.1}, "--eps-end"),
    (DQNConfig, {"gamma": float("nan")}, "--gamma"),
    (DQNConfig, {"hidden": (64, 2.5)}, "--hidden"),
    (DQNConfig, {"start": (1.5, 2), "target": (0, 0)}, "--start"),
    (OfflineConfig, {"n_steps": 0}, "--n-steps"),
    (OfflineConfig, {"lr": -1e-4}, "--lr"),
    (OfflineConfig, {"cql_alpha": float("nan")}, "--cql-alpha"),
    (OfflineConfig, {"eval_seed": -3}, "--eval-seed"),
    (OfflineConfig, {"max_steps": -1}, "--max-steps"),
    (AdaptConfig, {"seconds": float("inf")}, "--seconds"),
    (AdaptConfig, {"eps": 1.5}, "--eps"),
    (AdaptConfig, {"env_steps_per_update": 0}, "--env-steps-per-update"),
    (AdaptConfig, {"expert_margin": 0.0}, "--expert-margin"),
    (AdaptConfig, {"aug_obstacles": -2}, "--aug-obstacles"),
    (EvalConfig, {"max_steps": -1}, "--max-steps"),
    (EvalConfig, {"seed": -1}, "--seed"),
    (CrossConfig, {"pairs": 0}, "--pairs"),
]


@pytest.mark.parametrize("cls, changes, flag", BAD, ids=[f"{c.__name__}-{next(iter(ch))}" for c, ch, _ in BAD])
def test_a_nonsense_number_is_refused_when_the_config_is_made_naming_its_flag(cls, changes, flag):
    with pytest.raises(ConfigError, match=flag) as err:
        cls(**changes)  # no validate(): the config itself refuses
    assert isinstance(err.value, InvalidSettingError) and isinstance(err.value, ValueError)


def test_every_default_and_the_documented_sentinels_are_accepted():
    for cls in (DQNConfig, OfflineConfig, AdaptConfig, EvalConfig, CrossConfig, SweepConfig):
        cls()
    DQNConfig(lr_end=-1.0, max_steps=0, episodes=0, checkpoint_every=0, seed=3)  # constant lr, default limit, ...
    AdaptConfig(aug_obstacles=-1, expert_weight=0.0)  # -1 = as the checkpoint was trained


def test_a_saved_config_reads_back_and_a_replaced_one_is_checked_again():
    cfg = DQNConfig(scene="synthetic", total_env_steps=100)
    assert DQNConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ConfigError, match="--batch-size"):
        dataclasses.replace(cfg, batch_size=0)


def test_while_parsing_the_checks_wait_for_validate():
    with deferred_checks():
        cfg = DQNConfig(max_steps=-1)
    with pytest.raises(ConfigError, match="--max-steps"):
        cfg.validate()


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["train", "--scene", "synthetic", "--lr-end", "nan"], "--lr-end"),
        (["train", "--scene", "synthetic", "--max-steps", "-1"], "--max-steps"),
        (["train", "--scene", "synthetic", "--eps-start", "2"], "--eps-start"),
        (["offline", "--scene", "synthetic", "--cql-alpha", "inf"], "--cql-alpha"),
        (["adapt", "--scene", "synthetic", "--seconds", "nan"], "--seconds"),
        (["sweep", "--scenes", "synthetic", "--seeds", "0", "0", "--executor", "serial"], "--seeds"),
        (["sweep", "--scenes", "synthetic", "synthetic", "--executor", "serial"], "--scenes"),
        (["cross", "--scenes", "synthetic", "synthetic"], "--scenes"),
        (["eval", "--variants", "blueprint", "blueprint"], "--variants"),
        (["offline-bench", "--epsilon", "nan"], "--epsilon"),  # its validate() does not call the base: still checked
    ],
)
def test_on_the_command_line_each_is_one_error_line_exit_2_and_nothing_written(
    tmp_path, monkeypatch, capsys, argv, flag
):
    monkeypatch.chdir(tmp_path)
    assert main([*argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and flag in err.splitlines()[0] and "Traceback" not in err
    assert not (tmp_path / "run").exists() and not (tmp_path / "runs").exists()


def test_a_sweep_refuses_a_repeated_seed_that_would_fake_a_spread():
    with pytest.raises(ConfigError, match=r"--seeds repeats 0.*counted twice") as err:
        SweepConfig(scenes=("synthetic",), seeds=(0, 1, 0)).validate()
    assert "--seeds 0 1" in str(err.value)  # the fix names each seed once
    with pytest.raises(ConfigError, match="--seeds must be >= 0"):
        SweepConfig(scenes=("synthetic",), seeds=(-1,)).validate()
    SweepConfig(scenes=("synthetic",), seeds=(2, 0, 1)).validate()


def test_cross_checks_its_scene_names_before_loading_any_policy(root):
    with pytest.raises(UnknownNameError, match=r"scene \(--scenes\) 'synthetc'"):
        CrossConfig(scenes=("synthetic", "synthetc")).validate()
    with pytest.raises(DatasetNotFoundError, match="--scenes: cubicle/blueprint is not built"):
        CrossConfig(scenes=("synthetic-4x3", "cubicle")).validate()
    CrossConfig(scenes=("synthetic-4x3", "synthetic-5x3")).validate()  # synthetic twins need no store
