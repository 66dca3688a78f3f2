"""Offline agents with the default agent's senses: the memory window rebuilt from a log is the one the memory env
shows along the same moves, relabelled minibatches carry it, and an agent trained on it is evaluated in the memory
env with its loop escape."""

import json

import numpy as np
import pytest

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.envs.memory import MemoryGymEnv, MemoryNavEnv
from dtradar_rl.offline.config import ALGORITHMS, AUTO_SENSES, MEMORY_SETTINGS, OfflineConfig
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.memory_senses import MemorySenses, memory_senses
from dtradar_rl.offline.relabel import RelabelConfig
from dtradar_rl.offline.relabelled_sampler import relabelled_sampler
from dtradar_rl.offline.relabeller import relabeller
from dtradar_rl.offline.trainer import mdp_dataset, train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DQNConfig

SMALL = "synthetic-12x8"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A data root of this module with the small twin and a short noisy-shortest log on it."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp_path_factory.mktemp("root")))
        twin = load_dataset(f"{SMALL}/blueprint")
        cfg = LogConfig(
            scene=SMALL, num_envs=16, max_steps=20, seed=3, minari=False, verbose=False, behaviour="noisy-shortest"
        )
        yield twin, log_dataset(LogConfig(**{**cfg.to_dict(), "steps": 2_000}), twin)


def _replayed(twin, logged, senses, bumps):
    """(rows whose observation or next observation differs from the gym memory env's, rows compared)."""
    a = logged.arrays()
    ext = senses.arrays(a)
    env = MemoryGymEnv(
        twin,
        obs="neighbors",
        memory_radius=senses.layout.radius,
        memory_bumps=bumps,
        memory_visits=True,
        normalizer=Normalizer.from_dict(logged.meta["normalizer"]),
        max_steps=10_000,
    )
    xy = lambda c: tuple(int(v) for v in env.mdp.xy(int(c)))  # noqa: E731
    bad, seen = [], 0
    for s in np.flatnonzero(a["step"] == 0):
        o, _ = env.reset(options={"start": xy(a["cell"][s]), "target": xy(a["target"][s])})
        i = s
        while True:
            seen += 1
            if not np.array_equal(o, ext["obs"][i]):
                bad.append(i)
            o, *_ = env.step(int(a["action"][i]))
            if not np.array_equal(o, ext["next_obs"][i]):
                bad.append(i)
            if a["terminated"][i] or a["truncated"][i]:
                break
            i += 1
    return bad, seen


@pytest.mark.parametrize("bumps", [False, True])
def test_the_memory_window_rebuilt_from_a_log_is_what_the_memory_env_shows_along_the_same_moves(store, bumps):
    twin, logged = store
    senses = MemorySenses(logged, GridMDP.from_dataset(twin), radius=3, bumps=bumps, visits=True)
    bad, seen = _replayed(twin, logged, senses, bumps)
    assert seen == len(logged.arrays()["action"]) and not bad
    a = logged.arrays()
    assert GridMDP.from_dataset(twin).collides[a["cell"].astype(int), a["action"].astype(int)].any()  # bumps tested
    assert senses.window[:, -1].max() >= 2  # visit counts tested (a loop escape would fire)


def test_memory_senses_are_the_default_online_agents_window():
    d = DQNConfig()
    assert {k: getattr(d, k) for k in MEMORY_SETTINGS} == MEMORY_SETTINGS


def test_relabelled_minibatches_carry_the_memory_window_of_their_rows_whatever_the_goal(store):
    twin, logged = store
    senses = memory_senses(logged, GridMDP.from_dataset(twin))
    data = mdp_dataset(logged, senses)
    mix = RelabelConfig(own=0.2, future=0.4, random=0.4, seed=1)
    sampler = relabelled_sampler(data, relabeller(logged, twin), mix, senses)
    base_dim = logged.arrays()["obs"].shape[1]
    np.random.seed(0)
    batch = sampler.sample_transition_batch(64)
    np.random.seed(0)
    idx = np.random.randint(sampler.transition_count, size=64)
    assert batch.observations.shape == (64, base_dim + senses.dim)
    np.testing.assert_array_equal(batch.observations[:, base_dim:], senses.window[idx])
    live = batch.terminals[:, 0] == 0
    np.testing.assert_array_equal(batch.next_observations[live, base_dim:], senses.window[senses.next_row[idx[live]]])
    assert (batch.next_observations[~live] == 0).all()


def test_an_agent_trained_with_memory_senses_is_evaluated_in_the_memory_env_with_its_escape(store, tmp_path):
    twin, logged = store
    cfg = OfflineConfig(
        scene=SMALL, algorithm="bc", senses="memory", n_steps=60, pairs=20, eval_variants=("blueprint",),
        latency=False, shield=False, verbose=False, out=str(tmp_path / "run"),
    )  # fmt: skip
    r = train_offline(cfg, dataset=logged)
    meta = json.loads((tmp_path / "run" / "config.json").read_text())
    assert meta["obs"]["senses"] == "memory" and meta["obs"]["names"][-1] == "visits_here"
    assert r.policy.escape_after == MEMORY_SETTINGS["escape_after"]
    env = r.policy.env_for(twin, 4)
    assert isinstance(env, MemoryNavEnv) and env.obs_dim == len(meta["obs"]["names"])
    assert r.rows and r.rows[0]["dataset"] == f"{SMALL}/blueprint"
    assert r.data.episodes[0].observations.shape[1] == env.obs_dim  # what FQE replays


def test_unknown_senses_get_did_you_mean_and_memory_needs_the_neighbors_observation():
    with pytest.raises(UnknownNameError, match="memory"):
        OfflineConfig(senses="memroy").validate()
    with pytest.raises(ConfigError, match="neighbors"):
        OfflineConfig(senses="memory", obs="goal").validate()


def test_auto_senses_give_each_algorithm_its_measured_best_and_memoryless_where_the_memory_cannot_read():
    assert set(AUTO_SENSES) == set(ALGORITHMS)
    assert OfflineConfig(algorithm="dqn").resolved_senses == "memory"
    assert OfflineConfig(algorithm="bc").resolved_senses == "none"
    assert OfflineConfig(algorithm="dqn", obs="goal").resolved_senses == "none"
    assert OfflineConfig(algorithm="dqn").escape_after == MEMORY_SETTINGS["escape_after"]
    assert OfflineConfig(algorithm="dqn", senses="none").memory_radius == 0
    # a run saved before senses existed keeps its meaning: memoryless
    assert OfflineConfig.from_dict({"algorithm": "dqn"}).resolved_senses == "none"
