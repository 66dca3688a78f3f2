"""The default agent trains end to end on a twin with two transmitters: its checkpoint keeps both transmitters'
normaliser columns, evaluates on the twin, and is refused on a twin with one transmitter."""

import pytest
import torch

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.observations import obs_dim, observation_columns
from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy

TINY = dict(
    scene="synthetic-12x8",
    num_envs=16,
    total_env_steps=600,
    hidden=(16,),
    batch_size=32,
    learning_starts=100,
    env_steps_per_update=4,
    threads=1,
    verbose=False,
    checkpoint_every=0,
)


def test_the_default_agent_trains_on_two_transmitters_and_is_refused_on_a_twin_with_one(tmp_path, two_tx, tx_twin):
    cfg = config_for(DEFAULT_PRESET, out=str(tmp_path / "run"), **TINY)
    assert cfg.obs == "neighbors" and cfg.memory_radius and cfg.noise != "none"  # the default agent
    result = train(cfg, dataset=two_tx)
    policy = load_policy(result.checkpoint)
    assert policy.normalizer.columns == observation_columns(two_tx) and policy.normalizer.transmitters == 2
    state = torch.load(result.checkpoint, weights_only=False)
    names = state["obs"]["names"]
    assert "tx1_has_path" in names and state["arch"]["in_dim"] == len(names)
    assert policy.observations(two_tx).dim == obs_dim("neighbors", 2, cfg.sense_radius)
    metrics, _ = evaluate(policy, two_tx, pairs=20)
    assert 0.0 <= metrics.success_rate <= 1.0
    with pytest.raises(InvalidSettingError, match=r"observes 2 transmitter\(s\), .* has 1"):
        evaluate(policy, tx_twin(k=1), pairs=20)
