"""The default agent: a localisation filter over the blueprint's fingerprints, acting by QMDP on exact distances."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import CorruptDatasetError, InvalidSettingError, UnknownNameError
from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent, load_agent
from dtradar_rl.evaluation.evaluate import evaluate, sample_eval_pairs
from dtradar_rl.task.twins import load_dataset


@pytest.fixture(scope="module")
def blueprint():
    return load_dataset("synthetic/blueprint")


def test_the_radio_filter_reaches_every_target_on_the_blueprint_and_the_dynamic_twin_under_realistic_noise(blueprint):
    agent = RadioFilterAgent(blueprint, FilterConfig(scene="synthetic"))
    for variant, spl in (("blueprint", 0.98), ("dynamic", 0.95)):
        m, _ = evaluate(agent, load_dataset(f"synthetic/{variant}"), pairs=150, noise="realistic", latency=False)
        assert m.success_rate == 1.0 and m.spl >= spl, (variant, m)


def test_the_radio_carries_the_agents_path_length_no_radio_is_worse(blueprint):
    twin = load_dataset("synthetic/blueprint")
    spl = {}
    for sensing in ("radio", "no-radio"):
        agent = RadioFilterAgent(blueprint, FilterConfig(scene="synthetic", sensing=sensing))
        spl[sensing] = evaluate(agent, twin, pairs=150, noise="realistic", latency=False)[0].spl
    assert spl["radio"] >= spl["no-radio"] + 0.15, spl


def test_the_belief_finds_the_true_cell_within_a_few_steps(blueprint):
    agent = RadioFilterAgent(blueprint, FilterConfig(scene="synthetic"))
    pairs = sample_eval_pairs(blueprint, 64, seed=5)
    env = agent.env_for(blueprint, 64, noise="realistic", seed=5, reward="paper")
    env.reset_where(torch.ones(64, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    for _ in range(3):
        env.step(agent.act(env.observe()))
    agent.act(env.observe())  # the belief after the fourth reading
    located = agent.log_belief.argmax(1) == env.cell
    assert located.float().mean() >= 0.9


def test_a_saved_agent_loads_on_its_map_version_and_acts_the_same(blueprint, tmp_path):
    agent = RadioFilterAgent(blueprint, FilterConfig(scene="synthetic", sensing="rssi"))
    path = agent.save(tmp_path / "agent.json")
    record = json.loads(path.read_text())
    assert record["map"] == {"name": blueprint.name, "version": blueprint.version}
    assert record["config"]["sensing"] == "rssi" and "not told its position" in record["observes"]
    again = load_agent(path)
    a, _ = evaluate(agent, blueprint, pairs=40, latency=False)
    b, _ = evaluate(again, blueprint, pairs=40, latency=False)
    assert (a.success_rate, a.spl, a.steps) == (b.success_rate, b.spl, b.steps)


def test_a_damaged_agent_file_is_a_typed_error_naming_the_fix(tmp_path):
    path = tmp_path / "agent.json"
    path.write_text("{not json")
    with pytest.raises(CorruptDatasetError, match="make train"):
        load_agent(path)


def test_the_filter_refuses_the_privileged_sensing_and_names_unknown_ones():
    with pytest.raises(InvalidSettingError, match="honest"):
        FilterConfig(sensing="privileged").validate()
    with pytest.raises(UnknownNameError, match="did you mean"):
        FilterConfig(sensing="radi").validate()


def test_a_twin_with_another_transmitter_count_is_refused(blueprint, two_tx):
    agent = RadioFilterAgent(blueprint, FilterConfig(scene="synthetic"))
    with pytest.raises(InvalidSettingError, match="transmitter"):
        agent.env_for(two_tx, 1)


def test_the_filter_localises_on_a_twin_with_two_transmitters(two_tx):
    agent = RadioFilterAgent(two_tx, FilterConfig(scene="two-tx"))
    m, _ = evaluate(agent, two_tx, pairs=100, noise="realistic", latency=False)
    assert m.success_rate == 1.0 and m.spl >= 0.95
    assert np.isfinite(m.steps)


def test_on_a_moving_twin_the_filter_waits_for_movers_and_reaches_its_targets():
    for name in ("synthetic-moving/blueprint", "synthetic-moving-12x8/blueprint"):  # the small one: dense movers
        moving = load_dataset(name)
        agent = RadioFilterAgent(moving, FilterConfig(scene=name.split("/")[0]))
        m, r = evaluate(agent, moving, pairs=100, noise="realistic", latency=False)
        assert agent.forget and r.t0 is not None
        assert m.success_rate >= 0.95 and m.spl >= 0.9 and m.mover_collisions is not None, (name, m)
