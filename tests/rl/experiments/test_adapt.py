import json

import pytest

from dtradar_rl.experiments.adapt import AdaptConfig, adapt, first_time_at
from dtradar_rl.task.config import ConfigError
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train


def test_a_tiny_adapt_run_fine_tunes_a_blueprint_agent_and_compares_it_with_training_from_scratch(tmp_path):
    cfg = config_for(
        "memory",
        scene="synthetic-12x8",
        total_env_steps=400,
        num_envs=16,
        learning_starts=100,
        memory_radius=2,
        out=str(tmp_path / "dqn"),
        verbose=False,
        threads=1,
    )
    ckpt = train(cfg).checkpoint
    result = adapt(
        AdaptConfig(
            scene="synthetic-12x8",
            checkpoint=str(ckpt),
            seconds=0.4,
            eval_every_s=0.4,
            pairs=10,
            learning_starts=64,
            out=str(tmp_path / "adapt"),
            verbose=False,
            threads=1,
        )
    )
    curves = result.curves
    assert set(curves) == {"finetune", "finetune-dqn", "scratch"}
    assert curves["finetune"][0]["train_s"] == 0.0 and curves["finetune"][-1]["train_s"] >= 0.4
    assert curves["scratch"][-1]["train_s"] >= 0.4
    for name in ("curve.png", "curve.csv", "adapt.md", "adapt.json"):
        assert (tmp_path / "adapt" / name).is_file()
    saved = json.loads((tmp_path / "adapt" / "adapt.json").read_text())
    assert saved["curves"]["finetune"] == curves["finetune"]


def test_first_time_at_reads_the_curve():
    rows = [{"train_s": 0.0, "success_rate": 0.8}, {"train_s": 2.0, "success_rate": 0.99}]
    assert first_time_at(rows, 0.99) == 2.0 and first_time_at(rows, 1.0) is None


def test_adapting_a_checkpoint_without_the_geodesic_reward_asks_for_plain_fine_tuning(tmp_path):
    cfg = config_for(
        "tuned",
        scene="synthetic-12x8",
        reward="scaled",
        total_env_steps=200,
        num_envs=8,
        learning_starts=50,
        out=str(tmp_path / "dqn"),
        verbose=False,
        threads=1,
    )
    ckpt = train(cfg).checkpoint
    with pytest.raises(ConfigError, match="expert-weight 0"):
        adapt(AdaptConfig(scene="synthetic-12x8", checkpoint=str(ckpt), seconds=0.2, out=str(tmp_path / "a")))
    result = adapt(
        AdaptConfig(
            scene="synthetic-12x8",
            checkpoint=str(ckpt),
            seconds=0.2,
            eval_every_s=0.2,
            pairs=5,
            learning_starts=16,
            expert_weight=0.0,
            scratch=False,
            verbose=False,
            threads=1,
            out=str(tmp_path / "a"),
        )
    )
    assert set(result.curves) == {"finetune"}
