"""DQN: learns the optimal action on a tiny table, is seeded and resumable, writes checkpoints, configs and curves."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DQNConfig, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy

TINY = dict(
    scene="synthetic-4x3",
    obs="goal",
    reward="geodesic",
    num_envs=32,
    total_env_steps=16_000,
    hidden=(64, 64),
    batch_size=128,
    learning_starts=1_000,
    env_steps_per_update=4,
    target_update_every=100,
    eps_decay_fraction=0.5,
    threads=1,
    verbose=False,
    checkpoint_every=0,
)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_dqn_on_a_tiny_table_learns_the_optimal_action_everywhere(tmp_path):
    result = train(config_for("tuned", out=str(tmp_path), **TINY))
    policy = load_policy(result.checkpoint)
    ds = load_dataset("synthetic-4x3/blueprint")
    mdp = GridMDP.from_dataset(ds)
    table = policy.observations(ds)
    free = np.flatnonzero(mdp.free)
    wrong = []
    for t in free:
        dist = mdp.bfs_distances(int(t))
        for c in free:
            if c == t:
                continue
            a = int(policy.act(torch.from_numpy(table.observe(c, t))[None])[0])
            if dist[mdp.next_cell[c, a]] != dist[c] - 1:
                wrong.append((mdp.xy(c), mdp.xy(t), a))
    assert not wrong, f"non-optimal greedy actions: {wrong}"


def test_training_is_seeded(tmp_path):
    cfg = dict(TINY, total_env_steps=3_000)
    a = train(config_for("tuned", out=str(tmp_path / "a"), **cfg))
    b = train(config_for("tuned", out=str(tmp_path / "b"), **cfg))
    qa, qb = load_policy(a.checkpoint).q.state_dict(), load_policy(b.checkpoint).q.state_dict()
    assert all(torch.equal(qa[k], qb[k]) for k in qa)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
@pytest.mark.parametrize("expert_weight", [0.0, 1.0])
def test_resumed_training_equals_an_uninterrupted_run(tmp_path, expert_weight):
    cfg = dict(
        TINY,
        buffer_size=1_000,
        eps_start=0.3,
        eps_end=0.3,
        lr_end=-1.0,  # budget-independent
        expert_weight=expert_weight,
    )  # with the expert loss, last.pt also carries the replay's expert moves
    full = train(config_for("tuned", out=str(tmp_path / "full"), **dict(cfg, total_env_steps=4_000)))
    train(config_for("tuned", out=str(tmp_path / "res"), **dict(cfg, total_env_steps=2_000)))
    resumed = train(config_for("tuned", out=str(tmp_path / "res"), resume=True, **dict(cfg, total_env_steps=4_000)))
    assert resumed.env_steps == full.env_steps and resumed.updates == full.updates
    qa, qb = load_policy(full.checkpoint).q.state_dict(), load_policy(resumed.checkpoint).q.state_dict()
    assert all(torch.equal(qa[k], qb[k]) for k in qa)


def test_checkpoint_carries_config_and_normaliser_and_curves_are_written(tmp_path):
    result = train(config_for("tuned", out=str(tmp_path), **dict(TINY, total_env_steps=2_000)))
    for name in ("model.pt", "last.pt", "config.json", "curves.csv", "curves.png"):
        assert (tmp_path / name).exists(), name
    policy = load_policy(result.checkpoint)
    assert policy.config.obs == "goal" and policy.obs_preset == "goal"
    assert policy.normalizer.columns[:2] == ("x_m", "y_m")
    assert json.loads((tmp_path / "config.json").read_text())["reward"] == "geodesic"
    header = (tmp_path / "curves.csv").read_text().splitlines()[0]
    assert header == "episode,env_step,reward,steps,collisions,success"


def test_paper_preset_matches_the_paper():
    cfg = config_for("paper", scene="cubicle")
    assert cfg.hidden == (256,) * 5 and cfg.gamma == 0.9 and cfg.eps_start == cfg.eps_end == 0.1
    assert cfg.episodes == 500 and cfg.obs == "paper" and cfg.reward == "paper" and cfg.num_envs == 1
    assert config_for("paper", scene="dallas-q1").episodes == 80


def test_paper_preset_trains_for_its_episode_budget(tmp_path):
    result = train(
        config_for(
            "paper",
            scene="synthetic-6x5",
            episodes=3,
            learning_starts=16,
            out=str(tmp_path),
            threads=1,
            verbose=False,
            checkpoint_every=0,
        )
    )
    assert result.episodes == 3 and result.updates > 0
    assert load_policy(result.checkpoint).obs_preset == "paper"


def test_bad_settings_raise_typed_errors():
    with pytest.raises(UnknownNameError, match="paper"):
        config_for("papr")
    with pytest.raises(ConfigError, match="gamma"):
        DQNConfig(gamma=1.5).validate()
    with pytest.raises(UnknownNameError):
        DQNConfig(obs="gaol").validate()
