"""``--wait-action`` and ``--clock``: off by default, checked like every setting, saved with the model (the action
count in its architecture, checked against its config when loaded) and honoured when the checkpoint acts (the
evaluation env has the wait and observes the clock); a resumed run must keep both."""

import json

import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.agents.checkpoints import CheckpointError
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, DQNConfig, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import RunFolderError, load_policy

SCENE = "synthetic-moving-12x8"
TINY = dict(
    scene=SCENE,
    variant="blueprint",
    num_envs=16,
    total_env_steps=600,
    hidden=(32,),
    batch_size=64,
    learning_starts=200,
    env_steps_per_update=4,
    threads=1,
    verbose=False,
    checkpoint_every=0,
)


def test_both_are_off_by_default_and_round_trip_through_the_config():
    assert not config_for().wait_action and config_for().clock == "none"
    cfg = config_for(scene=SCENE, wait_action=True, clock="sincos")
    assert DQNConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    old = {k: v for k, v in cfg.to_dict().items() if k not in ("wait_action", "clock")}  # saved before them
    restored = DQNConfig.from_dict(old)
    assert not restored.wait_action and restored.clock == "none"


def test_an_unknown_clock_names_the_choices():
    with pytest.raises(UnknownNameError, match="sincos"):
        config_for(clock="phase")


def test_a_checkpoint_with_the_wait_and_the_clock_acts_with_five_actions_and_observes_the_phase(tmp_path):
    out = tmp_path / "run"
    result = train(config_for(DEFAULT_PRESET, out=str(out), wait_action=True, clock="sincos", sense_radius=2, **TINY))
    state = torch.load(result.checkpoint, weights_only=False)
    assert state["arch"]["n_actions"] == 5
    policy = load_policy(result.checkpoint)
    assert policy.wait_action and policy.clock == "sincos" and policy.q.net[-1].out_features == 5
    ds = load_dataset(f"{SCENE}/blueprint")
    env = policy.env_for(ds, 4)
    assert env.num_actions == 5 and env.obs_dim == policy.q.net[0].in_features
    assert "clock_sin" in env.obs_names and policy.observations(ds).clock == "sincos"
    for shield in (False, True):  # the shield and the mover guard take the fifth action
        metrics, _ = evaluate(policy, ds, pairs=8, latency=False, shield=shield)
        assert 0.0 <= metrics.success_rate <= 1.0
    assert load_policy(out / "last.pt").q.net[-1].out_features == 5  # the training state's weights give the count
    with pytest.raises(RunFolderError, match="--wait-action"):
        train(config_for(DEFAULT_PRESET, out=str(out), resume=True, clock="sincos", **{**TINY, "total_env_steps": 800}))


def test_a_checkpoint_whose_action_count_is_not_its_configs_is_refused(tmp_path):
    result = train(config_for(DEFAULT_PRESET, out=str(tmp_path / "run"), **TINY))
    state = torch.load(result.checkpoint, weights_only=False)
    cfg = json.loads(state["config"])
    state["config"] = json.dumps({**cfg, "wait_action": True})  # a network of four actions that claims a fifth
    bad = tmp_path / "bad.pt"
    torch.save(state, bad)
    with pytest.raises(CheckpointError, match="4 actions, its config \\(--wait-action=True\\) 5"):
        load_policy(bad)


def test_the_movers_penalty_is_one_by_default_and_never_negative():
    from dtradar_rl.task.config import ConfigError

    assert config_for().mover_penalty == 1.0
    with pytest.raises(ConfigError, match="--mover-penalty must be >= 0"):
        config_for(mover_penalty=-1.0)
