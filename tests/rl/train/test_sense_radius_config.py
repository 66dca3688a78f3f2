"""``--sense-radius``: 1 by default, checked like every setting (a typed error naming the flag), saved with the model
and honoured when the checkpoint is loaded to act (the evaluation env observes the ring the network was trained on);
a resumed run must keep it."""

import json

import pytest

from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, DQNConfig, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import RunFolderError, load_policy

SCENE = "synthetic-moving-12x8"
TINY = dict(
    scene=SCENE,
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


def test_the_default_is_the_four_neighbours_and_a_radius_round_trips_through_the_config():
    assert config_for().sense_radius == 1 == config_for("tuned").sense_radius
    cfg = config_for(scene=SCENE, sense_radius=4)
    assert DQNConfig.from_dict(json.loads(json.dumps(cfg.to_dict()))) == cfg
    old = {k: v for k, v in cfg.to_dict().items() if k != "sense_radius"}  # a config.json from before the setting
    assert DQNConfig.from_dict(old).sense_radius == 1


@pytest.mark.parametrize(
    "bad, match", [(0, ">= 1"), (-1, ">= 1"), (2.5, "an integer"), (True, "an integer"), ("3", "an integer")]
)
def test_a_bad_sense_radius_names_its_flag(bad, match):
    with pytest.raises(ConfigError, match=f"--sense-radius must be {match}"):
        config_for(sense_radius=bad)


def test_a_wider_radius_needs_the_neighbors_observation():
    with pytest.raises(ConfigError, match="--sense-radius 2.*--obs goal"):
        config_for("tuned", obs="goal", sense_radius=2)


def test_a_checkpoint_trained_with_a_wider_radius_observes_it_again_when_loaded(tmp_path):
    out = tmp_path / "run"
    result = train(config_for(DEFAULT_PRESET, out=str(out), variant="blueprint", sense_radius=2, **TINY))
    assert json.loads((out / "config.json").read_text())["sense_radius"] == 2
    policy = load_policy(result.checkpoint)
    assert policy.config.sense_radius == policy.sense_radius == 2
    ds = load_dataset(f"{SCENE}/blueprint")
    env = policy.env_for(ds, 4)
    assert env.obs_dim == policy.q.net[0].in_features and env.obs_table.sense_radius == 2
    assert "has_radio_before[+0,+2]" in env.obs_names
    assert policy.observations(ds).sense_radius == 2
    for shield in (False, True):  # the shield and the mover guard read the neighbours' flags where they always were
        metrics, _ = evaluate(policy, ds, pairs=8, latency=False, shield=shield)
        assert 0.0 <= metrics.success_rate <= 1.0
    with pytest.raises(RunFolderError, match="--sense-radius 2 \\(now 3\\)"):
        train(config_for(DEFAULT_PRESET, out=str(out), sense_radius=3, resume=True, **{**TINY, "total_env_steps": 800}))
