"""A logged dataset's Minari copy with the default agent's senses (``--minari-memory``, ``export_minari(...,
senses="memory")``): ``<id>-memory`` holds every step with its memory window, rebuilt from the log, and its
``recover_environment()`` is the memory env on the logging twin, which replays a logged episode observation for
observation; the plain copy is unchanged beside it, and the flag is refused where it cannot apply. Tiny twins."""

import dataclasses
import json

import numpy as np
import pytest

from dtradar_rl.envs.memory import MemoryGymEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.offline import minari_copy
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.minari_envs import MINARI_MEMORY
from dtradar_rl.task.config import ConfigError

minari = pytest.importorskip("minari")

CFG = LogConfig(
    scene="synthetic-8x6",
    behaviour="noisy-shortest",
    steps=360,
    num_envs=6,
    max_steps=12,
    seed=3,
    minari_memory=True,
    verbose=False,
)


@pytest.fixture()
def stores(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return root


def test_the_memory_copy_sits_beside_the_plain_one_and_recovers_the_memory_env(stores):
    logged = log_dataset(CFG)
    mid = minari_copy.copy_id(logged, "memory")
    assert mid == logged.minari_id.replace("-v0", "-memory-v0")
    plain, mem = minari.load_dataset(logged.minari_id), minari.load_dataset(mid)
    assert isinstance(plain.recover_environment().unwrapped, DtradarNavEnv)
    assert not isinstance(plain.recover_environment().unwrapped, MemoryGymEnv)
    env = mem.recover_environment()
    assert (
        isinstance(env.unwrapped, MemoryGymEnv) and env.spec.kwargs["memory_radius"] == MINARI_MEMORY["memory_radius"]
    )
    d = plain.observation_space.shape[0]
    assert mem.observation_space == env.observation_space and mem.observation_space.shape[0] > d
    assert mem.total_steps == plain.total_steps == len(logged)
    for p, m in zip(plain.iterate_episodes(), mem.iterate_episodes()):
        np.testing.assert_array_equal(m.observations[:, :d], p.observations)  # the logged part, then the window
        np.testing.assert_array_equal(m.actions, p.actions)
    rec = json.loads((minari_copy.minari_root() / mid / minari_copy.RECORD_FILE).read_text())
    assert rec["senses"] == "memory" and minari_copy.copy_state(minari_copy.minari_root() / mid, logged, "memory")[
        0
    ] == ("complete")
    assert minari_copy.copy_state(logged.minari_path, logged, "memory")[0] == "incomplete"  # not the memory copy


def test_a_logged_episode_replays_in_the_recovered_memory_env_observation_for_observation(stores):
    logged = log_dataset(CFG)
    a = logged.arrays()
    starts = np.flatnonzero(a["step"] == 0)
    mem = minari.load_dataset(minari_copy.copy_id(logged, "memory"))
    env = mem.recover_environment()
    mdp = env.unwrapped.mdp
    for ep, s in list(zip(mem.iterate_episodes(), starts))[:10]:
        start, target = (tuple(int(v) for v in mdp.xy(int(a[k][s]))) for k in ("cell", "target"))
        obs, _ = env.reset(seed=1, options={"start": start, "target": target})
        np.testing.assert_allclose(obs, ep.observations[0], atol=1e-6)
        for t, action in enumerate(ep.actions):
            obs, *_ = env.step(int(action))
            np.testing.assert_allclose(obs, ep.observations[t + 1], atol=1e-6, err_msg=f"episode {ep.id} step {t}")


def test_minari_memory_is_refused_without_a_minari_copy_or_without_the_neighbors_observation():
    with pytest.raises(ConfigError, match="--no-minari writes none"):
        dataclasses.replace(CFG, minari=False).validate()
    with pytest.raises(ConfigError, match="extends the neighbors observation"):
        dataclasses.replace(CFG, obs="paper").validate()
