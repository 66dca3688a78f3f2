"""Logged offline-RL datasets from the behaviour policies: alignment through Minari and d3rlpy, terminal versus
truncation, versions from the logging settings, mixtures, and typed errors for a log that does not fit a trainer."""

import dataclasses

import numpy as np
import pytest
import torch

import dtradar_data
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_rl.agents.checkpoints import save_checkpoint
from dtradar_rl.agents.policy import QNetwork
from dtradar_rl.offline.behaviours import BehaviourSpec
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.formats import d3rlpy_arrays, to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.minari_copy import export_minari, from_minari
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for

SMALL = "synthetic-10x8"
CFG = LogConfig(
    scene=SMALL, behaviour="noisy-shortest", steps=1200, num_envs=12, max_steps=15, seed=2, minari=False, verbose=False
)


@pytest.fixture()
def stores(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return root


@pytest.fixture(scope="module")
def twin():
    return load_dataset(f"{SMALL}/blueprint")


def test_transitions_are_aligned_through_minari_and_back(stores, twin):
    logged = log_dataset(CFG, twin)
    a = logged.arrays()
    mid = export_minari(logged)
    import minari

    m = minari.load_dataset(mid)
    assert (m.total_episodes, m.total_steps) == (logged.meta["stats"]["episodes"], len(logged))
    ep = next(m.iterate_episodes())
    n = len(ep.actions)
    assert len(ep.observations) == n + 1
    np.testing.assert_array_equal(ep.observations[:-1], a["obs"][:n])  # observation t
    np.testing.assert_array_equal(ep.actions, a["action"][:n])  # action t
    np.testing.assert_allclose(ep.rewards, a["reward"][:n])  # reward t
    np.testing.assert_array_equal(ep.observations[1:], a["next_obs"][:n])  # next observation = observation t+1
    back = from_minari(mid)
    for k, v in back.items():
        np.testing.assert_array_equal(v, a[k], err_msg=k)
    assert export_minari(logged) == mid  # the same version is kept, not written twice


def test_the_d3rlpy_dataset_keeps_every_transition_with_its_next_observation(stores, twin):
    logged = log_dataset(CFG, twin)
    a = logged.arrays()
    mdp = to_mdp_dataset(logged)
    assert mdp.transition_count == len(logged)
    ends = np.flatnonzero(a["terminated"] | a["truncated"]) + 1
    assert len(mdp.episodes) == len(ends)
    for ep, s, e in zip(mdp.episodes, np.r_[0, ends[:-1]], ends):
        np.testing.assert_array_equal(ep.observations[: e - s], a["obs"][s:e])
        np.testing.assert_array_equal(ep.actions[: e - s, 0], a["action"][s:e])
        np.testing.assert_allclose(ep.rewards[: e - s, 0], a["reward"][s:e])
        assert ep.terminated == bool(a["terminated"][e - 1])
        if not ep.terminated:  # the timeout row holds the final next observation
            np.testing.assert_array_equal(ep.observations[-1], a["next_obs"][e - 1])
    arr = d3rlpy_arrays(logged)
    assert not np.any((arr["terminals"] > 0) & (arr["timeouts"] > 0))


def test_terminal_steps_reach_the_target_and_truncations_are_the_step_limit_or_the_end_of_logging(stores, twin):
    a = log_dataset(CFG, twin).arrays()
    mdp = GridMDP.from_dataset(twin)
    table = build_observations(twin, "neighbors", Normalizer.fit(twin))
    nxt_cell = np.array([mdp.step(int(c), int(u))[0] for c, u in zip(a["cell"], a["action"])])
    np.testing.assert_array_equal(a["terminated"], nxt_cell == a["target"])
    np.testing.assert_array_equal(a["next_obs"], table.observe(nxt_cell, a["target"]))
    np.testing.assert_array_equal(a["obs"], table.observe(a["cell"], a["target"]))
    assert not np.any(a["terminated"] & a["truncated"])
    horizon = -(-CFG.steps // CFG.num_envs)
    last_of_robot = np.r_[a["robot"][1:] != a["robot"][:-1], True]
    trunc = np.flatnonzero(a["truncated"])
    assert np.all((a["step"][trunc] == CFG.max_steps - 1) | last_of_robot[trunc])
    assert np.all(a["truncated"][last_of_robot] | a["terminated"][last_of_robot])  # the budget ends every episode
    assert len(a["action"]) == horizon * CFG.num_envs  # nothing dropped


def test_logging_again_with_the_same_name_and_settings_reuses_the_version(stores, twin):
    first = log_dataset(CFG, twin)
    again = log_dataset(CFG, twin)
    assert (again.version, again.tag) == (first.version, "v0")
    other = log_dataset(dataclasses.replace(CFG, seed=3), twin)
    assert other.version != first.version and other.tag == "v1"
    assert log_dataset(dataclasses.replace(CFG, epsilon=0.9), twin).version == first.version  # unused by the kind
    assert dtradar_data.load(f"{SMALL}/blueprint/noisy-shortest@v0").version == first.version


def test_a_mixture_splits_the_robots_between_its_components_and_checkpoints_enter_the_version(stores, twin, tmp_path):
    norm = Normalizer.fit(twin)
    names = build_observations(twin, "neighbors", norm).names
    torch.manual_seed(0)
    ckpt = save_checkpoint(
        tmp_path / "model.pt",
        QNetwork(len(names), (8,)),
        dataclasses.replace(config_for("tuned", scene=SMALL), hidden=(8,)),
        norm,
        names,
        twin,
    )
    cfg = dataclasses.replace(CFG, behaviour="mixture", checkpoint=str(ckpt))
    logged = log_dataset(cfg, twin)
    a = logged.arrays()
    np.testing.assert_array_equal(a["component"], a["robot"] % 3)
    assert logged.meta["behaviour"]["components"] == ["random", "noisy-shortest", "epsilon-greedy"]
    assert len(logged.meta["behaviour"]["checkpoint_sha256"]) == 64
    with pytest.raises(ConfigError, match="checkpoint"):
        BehaviourSpec("epsilon-greedy").validate()
    eps = log_dataset(dataclasses.replace(cfg, behaviour="epsilon-greedy", epsilon=0.0), twin)
    assert eps.name == f"{SMALL}/blueprint/epsilon-greedy"

    memory = save_checkpoint(  # the default agent's memory is not in a logged step: refused, with the way out
        tmp_path / "memory" / "model.pt",
        QNetwork(len(names) + 3 * 9 + 1, (8,)),
        dataclasses.replace(config_for(scene=SMALL, memory_radius=1), hidden=(8,)),
        norm,
        [*names, *(f"memory{i}" for i in range(3 * 9 + 1))],
        twin,
    )
    with pytest.raises(ConfigError, match="memory agent") as e:
        log_dataset(dataclasses.replace(cfg, behaviour="epsilon-greedy", checkpoint=str(memory)), twin)
    assert "--preset tuned" in e.value.hint

    wide_names = build_observations(twin, "neighbors", norm, sense_radius=2).names
    wide = save_checkpoint(  # a wider sensing agent observes columns a logged step does not hold: refused, clearly
        tmp_path / "wide" / "model.pt",
        QNetwork(len(wide_names), (8,)),
        dataclasses.replace(config_for("tuned", scene=SMALL, sense_radius=2), hidden=(8,)),
        norm,
        wide_names,
        twin,
    )
    with pytest.raises(ConfigError, match="--sense-radius 2"):
        log_dataset(dataclasses.replace(cfg, behaviour="epsilon-greedy", checkpoint=str(wide)), twin)


def test_a_log_from_another_twin_or_preset_is_refused_by_the_trainer_with_a_typed_error(stores, twin, tmp_path):
    logged = log_dataset(CFG, twin)
    base = dict(
        scene=SMALL,
        algorithm="bc",
        n_steps=10,
        batch_size=16,
        hidden=(8,),
        eval_variants=(),
        verbose=False,
        out=str(tmp_path / "run"),
    )
    with pytest.raises(SchemaMismatchError, match="observation preset"):
        train_offline(OfflineConfig(**base, obs="goal"), dataset=logged)
    with pytest.raises(SchemaMismatchError, match="logged on"):
        train_offline(OfflineConfig(**dict(base, scene="synthetic-12x8")), dataset=logged)
    result = train_offline(OfflineConfig(**base, logged=logged.name))
    assert result.logged["source"] == f"{logged.name}@{logged.version}"
