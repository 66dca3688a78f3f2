"""The default budget grows with the twin: the paper's 600K, or 500 steps per free cell where that is more; a budget
given stays; training saves the steps it was given."""

import json

import pytest

import dtradar_rl.train.config as config_module
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import PRESETS, budget_for, config_for, with_budget
from dtradar_rl.train.dqn import train


def test_the_default_budget_is_the_papers_up_to_1200_free_cells_then_500_steps_per_cell():
    assert budget_for(592) == budget_for(1_200) == 600_000  # the cubicle; the largest twin 600K covers
    assert budget_for(1_950) == 975_000  # Dallas Q3
    assert budget_for(3_069) == 1_534_500  # Munich
    assert budget_for(592, moving=True) == 1_200_000  # the cubicle's movers
    assert budget_for(1_950, moving=True) == 1_950_000  # Dallas Q3's


def test_only_the_default_preset_has_the_growing_budget():
    assert config_for().total_env_steps == 0
    for preset in PRESETS:
        if preset not in ("memory-escape-noise-margin", "paper"):
            assert config_for(preset).total_env_steps == 600_000, preset
    assert config_for("paper").total_env_steps == 10_000_000  # the paper's episodes decide; a backstop


def test_a_budget_given_is_kept_and_the_default_one_is_resolved_from_the_free_cells():
    assert with_budget(config_for(total_env_steps=1234), 10_000).total_env_steps == 1234
    assert with_budget(config_for(), 3_069).total_env_steps == 1_534_500
    assert with_budget(config_for(), 3_069, moving=True).total_env_steps == 3_069_000


def test_a_negative_budget_is_refused_and_zero_means_the_default():
    with pytest.raises(config_module.ConfigError, match="total-env-steps"):
        config_for(total_env_steps=-1)
    assert config_for(total_env_steps=0).total_env_steps == 0


def test_training_with_the_default_budget_runs_and_saves_the_steps_it_was_given(tmp_path, monkeypatch):
    # the real rule with small constants, so the run is short: 30 steps per free cell of the 12 x 8 synthetic twin
    monkeypatch.setattr(config_module, "PAPER_BUDGET", 500)
    monkeypatch.setattr(config_module, "STEPS_PER_FREE_CELL", 30)
    free = int((~load_dataset("synthetic-12x8/blueprint").blocked).sum())
    cfg = config_for(
        "tuned",
        scene="synthetic-12x8",
        total_env_steps=0,
        num_envs=16,
        learning_starts=64,
        env_steps_per_update=16,
        threads=1,
        verbose=False,
        checkpoint_every=0,
        out=str(tmp_path / "run"),
    )
    result = train(cfg)
    assert 30 * free > 500
    assert result.env_steps >= 30 * free > result.env_steps - 16  # the last batch of 16 robots may overshoot
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_env_steps"] == 30 * free
