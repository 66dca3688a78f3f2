"""Every training run records the torch threads it used and its --threads setting (run.json and the checkpoint's
stats for DQN, config.json's stats offline), and eval shows them; config.json stays the config alone."""

import json

import torch

from dtradar_rl.cli import main
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy


def test_a_dqn_run_records_its_threads_and_eval_shows_them(tmp_path, capsys):
    cfg = config_for(
        "tuned",
        scene="synthetic-4x3",
        obs="goal",
        num_envs=8,
        total_env_steps=100,
        hidden=(8,),
        batch_size=16,
        learning_starts=50,
        threads=1,
        verbose=False,
        checkpoint_every=0,
        out=str(tmp_path / "run"),
    )
    result = train(cfg)
    record = json.loads((tmp_path / "run" / "run.json").read_text())
    assert record["stats"]["threads"] == 1 and record["stats"]["threads_setting"] == 1
    assert record["dataset"]["name"] == "synthetic-4x3/blueprint" and record["torch"] == torch.__version__
    assert load_policy(result.checkpoint).meta["stats"]["threads"] == 1
    assert json.loads((tmp_path / "run" / "config.json").read_text()) == json.loads(json.dumps(cfg.to_dict()))

    argv = ["eval", "--scene", "synthetic-4x3", "--checkpoint", str(result.checkpoint), "--pairs", "2"]
    assert main([*argv, "--no-planner", "--plot-paths", "0", "--out", str(tmp_path / "eval")]) == 0
    assert "trained with 1 torch thread(s) (--threads 1)" in capsys.readouterr().out
    saved = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert saved["config"]["train_stats"]["threads"] == 1


def test_an_offline_run_records_its_threads(root, tmp_path):
    cfg = OfflineConfig(
        scene="synthetic-4x3",
        algorithm="bc",
        num_envs=4,
        transitions=40,
        n_steps=10,
        batch_size=8,
        hidden=(8,),
        eval_variants=(),
        threads=1,
        verbose=False,
        out=str(tmp_path / "offline"),
    )
    train_offline(cfg)
    stats = json.loads((tmp_path / "offline" / "config.json").read_text())["stats"]
    assert stats["threads"] == 1 and stats["threads_setting"] == 1
