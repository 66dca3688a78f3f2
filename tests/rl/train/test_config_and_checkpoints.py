"""Trainer settings are checked before any work and name the --flag; checkpoints are written atomically and a
damaged one is a typed error naming the file."""

import dataclasses

import pytest
import torch

from dtradar_rl.agents.checkpoints import CheckpointError, read_checkpoint, save_torch_atomic
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.task.config import ConfigError
from dtradar_rl.train.config import DQNConfig, config_for
from dtradar_rl.train.saved_runs import load_policy


@pytest.mark.parametrize(
    "changes, flag",
    [
        ({"lr": 0.0}, "--lr"),
        ({"lr": -1e-3}, "--lr"),
        ({"max_steps": -5}, "--max-steps"),
        ({"total_env_steps": -1}, "--total-env-steps"),
        ({"gamma": 1.0}, "--gamma"),
        ({"num_envs": 0}, "--num-envs"),
        ({"eps_end": 1.5}, "--eps-end"),
        ({"hidden": (256, 0)}, "--hidden"),
        ({"lr_end": 0.0}, "--lr-end"),
    ],
)
def test_an_out_of_range_dqn_setting_names_its_flag(changes, flag):
    with pytest.raises(ConfigError, match=flag):
        config_for("tuned", **changes)


@pytest.mark.parametrize(
    "changes, flag",
    [
        ({"lr": 0.0}, "--lr"),
        ({"transitions": 0}, "--transitions"),
        ({"shortest_prob": 2.0}, "--shortest-prob"),
        ({"threads": -1}, "--threads"),
    ],
)
def test_an_out_of_range_offline_setting_names_its_flag(changes, flag):
    with pytest.raises(ConfigError, match=flag):
        OfflineConfig(**changes).validate()


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_asking_for_cuda_without_a_gpu_is_refused_before_training():
    with pytest.raises(ConfigError, match="no CUDA GPU"):
        config_for("tuned", device="cuda")


def test_both_trainers_share_the_twin_settings():
    shared = {f.name for f in dataclasses.fields(DQNConfig)} & {f.name for f in dataclasses.fields(OfflineConfig)}
    assert {"scene", "variant", "revision", "obs", "reward", "num_envs", "seed", "device", "threads"} <= shared


def test_a_config_round_trips_through_its_dict():
    cfg = config_for("paper", scene="synthetic")
    assert DQNConfig.from_dict(cfg.to_dict()) == cfg


@pytest.mark.parametrize("content", [b"", b"not a torch file", b"PK\x03\x04truncated"])
def test_a_garbage_or_truncated_checkpoint_is_a_typed_error_naming_the_file(tmp_path, content):
    path = tmp_path / "model.pt"
    path.write_bytes(content)
    with pytest.raises(CheckpointError, match="model.pt"):
        load_policy(path)


def test_a_checkpoint_of_another_kind_is_refused(tmp_path):
    path = save_torch_atomic({"format": "something-else/9"}, tmp_path / "model.pt")
    with pytest.raises(CheckpointError, match="something-else/9"):
        read_checkpoint(path, ("dtradar-dqn/1",), what="dtradar DQN checkpoint")
    with pytest.raises(CheckpointError, match="no checkpoint at"):
        load_policy(tmp_path / "missing.pt")


def test_an_interrupted_checkpoint_write_keeps_the_previous_file(tmp_path, monkeypatch):
    path = save_torch_atomic({"format": "dtradar-dqn/1", "n": 1}, tmp_path / "last.pt")

    def dies(obj, f):
        f.write(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(torch, "save", dies)
    with pytest.raises(KeyboardInterrupt):
        save_torch_atomic({"format": "dtradar-dqn/1", "n": 2}, path)
    monkeypatch.undo()
    assert torch.load(path, weights_only=False)["n"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["last.pt"]
