"""A Minari copy of a logged dataset records its env: ``recover_environment()`` gives the navigation env on the twin
and twin version the data was logged on, with the logged observation preset, reward and step limit (spaces equal to
the dataset's; a logged episode replays step for step from its start and target), ``eval_env=True`` the dynamic twin
with the training twin's normaliser (the logging twin itself for a log on the dynamic twin), in a fresh process that
imports only Minari too; a copy an older dtradar wrote without a spec is rewritten once. Tiny synthetic twins."""

import dataclasses
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dtradar_data.core.errors import SchemaMismatchError
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.envs.registration import TWIN_ENTRY_POINT, make_twin_env
from dtradar_rl.offline import minari_copy
from dtradar_rl.offline.logged import LogConfig, log_dataset

minari = pytest.importorskip("minari")

SMALL = "synthetic-8x6"
#: Settings that differ from the env's defaults (goal, paper, 4 * (nx + ny) = 56 steps), so a spec that dropped one
#: would make another env.
CFG = LogConfig(
    scene=SMALL,
    behaviour="noisy-shortest",
    steps=360,
    num_envs=6,
    max_steps=12,
    obs="neighbors",
    reward="euclidean",
    seed=3,
    verbose=False,
)


@pytest.fixture()
def stores(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return root


def assert_same_spaces(env, ds):
    assert env.observation_space == ds.observation_space and env.action_space == ds.action_space
    np.testing.assert_array_equal(env.observation_space.low, ds.observation_space.low)
    np.testing.assert_array_equal(env.observation_space.high, ds.observation_space.high)
    assert env.observation_space.dtype == ds.observation_space.dtype == np.float32


def test_the_recovered_env_is_the_logging_twin_at_its_version_with_the_logged_settings(stores):
    logged = log_dataset(CFG)
    ds = minari.load_dataset(logged.minari_id)
    env = ds.recover_environment()
    nav = env.unwrapped
    assert isinstance(nav, DtradarNavEnv) and nav.dataset_name == f"{SMALL}/blueprint"
    assert env.spec.entry_point == TWIN_ENTRY_POINT and env.spec.id == f"dtradar/{SMALL}-blueprint-privileged-v0"
    kw = env.spec.kwargs
    assert (kw["dataset"], kw["version"]) == (logged.meta["parent"], logged.meta["parent_version"])
    assert (nav.obs_preset, nav.reward_name, nav.max_steps) == ("neighbors", "euclidean", 12)
    assert kw["normalizer"] == logged.meta["normalizer"] and nav.noise is None
    assert_same_spaces(env, ds)
    for ep in ds.iterate_episodes():
        assert all(ds.observation_space.contains(o) for o in ep.observations)
    obs, _ = env.reset(seed=0)
    assert ds.observation_space.contains(obs)
    for action in (0, 1, 2, 3, 3):
        obs, reward, *_ = env.step(action)
        assert ds.observation_space.contains(obs) and np.isfinite(reward)
    rec = json.loads((logged.minari_path / minari_copy.RECORD_FILE).read_text())
    assert rec["format"] == minari_copy.RECORD_FORMAT == 3 and rec["env_spec"]["kwargs"] == kw
    assert "recover_environment()" in ds.storage.metadata["description"]


def test_a_logged_episode_replays_step_for_step_from_its_start_and_target(stores):
    logged = log_dataset(CFG)
    a = logged.arrays()
    starts = np.flatnonzero(a["step"] == 0)
    env = minari.load_dataset(logged.minari_id).recover_environment()
    mdp = env.unwrapped.mdp
    episodes = list(minari.load_dataset(logged.minari_id).iterate_episodes())
    assert len(episodes) == len(starts)
    truncated_by_limit = 0
    for ep, s in list(zip(episodes, starts))[:12]:
        start, target = (tuple(int(v) for v in mdp.xy(int(a[k][s]))) for k in ("cell", "target"))
        obs, info = env.reset(seed=1, options={"start": start, "target": target})
        assert info["cell"] == start
        np.testing.assert_array_equal(obs, ep.observations[0])
        for t, action in enumerate(ep.actions):
            obs, reward, term, trunc, _ = env.step(int(action))
            np.testing.assert_array_equal(obs, ep.observations[t + 1], err_msg=f"episode {ep.id} step {t}")
            assert reward == pytest.approx(ep.rewards[t], rel=1e-5, abs=1e-6)
            assert term == ep.terminations[t]
            assert not trunc or ep.truncations[t]  # the data also cuts episodes at the end of logging
            truncated_by_limit += trunc
    assert truncated_by_limit, "some replayed episode hit the 12-step limit"


def test_the_evaluation_env_is_the_dynamic_twin_with_the_training_twins_normaliser(stores):
    logged = log_dataset(CFG)
    ds = minari.load_dataset(logged.minari_id)
    ev = ds.recover_environment(eval_env=True)
    nav = ev.unwrapped
    assert nav.dataset_name == f"{SMALL}/dynamic" and ev.spec.id == f"dtradar/{SMALL}-dynamic-privileged-v0"
    assert nav.normalizer.to_dict() == logged.meta["normalizer"]
    assert (nav.obs_preset, nav.reward_name, nav.max_steps) == ("neighbors", "euclidean", 12)
    assert ev.action_space == ds.action_space and ev.observation_space.shape == ds.observation_space.shape
    assert nav.mdp.blocked.sum() > ds.recover_environment().unwrapped.mdp.blocked.sum()  # the dynamic obstacles

    on_dynamic = log_dataset(dataclasses.replace(CFG, variant="dynamic"))
    dyn = minari.load_dataset(on_dynamic.minari_id)
    assert dyn.recover_environment(eval_env=True).spec == dyn.recover_environment().spec
    assert dyn.recover_environment(eval_env=True).unwrapped.dataset_name == f"{SMALL}/dynamic"


FRESH = textwrap.dedent("""
    import sys

    import minari

    assert not [m for m in sys.modules if m.startswith("dtradar")], "minari imported dtradar"
    ds = minari.load_dataset(sys.argv[1])
    for eval_env in (False, True):
        env = ds.recover_environment(eval_env=eval_env)
        obs, _ = env.reset(seed=0)
        assert obs.shape == ds.observation_space.shape
        obs, *_ = env.step(1)
        print(env.unwrapped.dataset_name, env.observation_space == ds.observation_space)
""")


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_fresh_process_that_imports_only_minari_recovers_both_envs(stores):
    logged = log_dataset(CFG)
    out = subprocess.run(
        [sys.executable, "-c", FRESH, logged.minari_id],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=stores.parent,  # not the repository: dtradar comes from the installed package
        env={**os.environ},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split("\n")[:2] == [f"{SMALL}/blueprint True", f"{SMALL}/dynamic False"]


def test_a_copy_an_older_dtradar_wrote_without_an_env_spec_is_rewritten_once(stores, monkeypatch):
    logged = log_dataset(dataclasses.replace(CFG, minari=False))
    with monkeypatch.context() as m:  # what format 1 wrote: no env spec, an unbounded observation space
        m.setattr(minari_copy, "RECORD_FORMAT", 1)
        m.setattr(minari_copy, "minari_envs", lambda *_: minari_copy.MinariEnvs(missing="format 1"))
        with pytest.warns(UserWarning, match="no env spec"):
            minari_copy.export_minari(logged)
    folder = logged.minari_path
    with pytest.raises(ValueError, match="env_spec is None"):
        minari.load_dataset(logged.minari_id).recover_environment()
    state, why = minari_copy.copy_state(folder, logged)
    assert state == "incomplete" and "record format 1" in why
    minari_copy.export_minari(logged)
    ds = minari.load_dataset(logged.minari_id)
    assert_same_spaces(ds.recover_environment(), ds)
    assert minari_copy.copy_state(folder, logged)[0] == "complete"
    written = (folder / "data" / "metadata.json").stat().st_mtime_ns
    minari_copy.export_minari(logged)
    assert (folder / "data" / "metadata.json").stat().st_mtime_ns == written, "a complete copy is not rewritten"


def test_a_copy_written_while_its_twin_was_missing_gets_its_spec_once_the_twin_is_here(stores):
    logged = log_dataset(dataclasses.replace(CFG, minari=False))
    elsewhere = dataclasses.replace(logged, meta={**logged.meta, "parent": "nowhere/blueprint"})
    with pytest.warns(UserWarning, match="nowhere/blueprint"):
        minari_copy.export_minari(elsewhere)
    rec = json.loads((logged.minari_path / minari_copy.RECORD_FILE).read_text())
    assert rec["env_spec"] is None and rec["env_retry"] and "nowhere/blueprint" in rec["env_missing"]
    assert minari_copy.copy_state(logged.minari_path, elsewhere)[0] == "complete"  # still missing: kept
    state, why = minari_copy.copy_state(logged.minari_path, logged)
    assert state == "incomplete" and "the twin is here now" in why
    minari_copy.export_minari(logged)
    ds = minari.load_dataset(logged.minari_id)
    assert_same_spaces(ds.recover_environment(), ds)


def test_a_pinned_twin_at_another_version_is_refused_by_name(root):
    with pytest.raises(SchemaMismatchError, match=f"{SMALL}/blueprint is version sha256:.* pins sha256:0000"):
        make_twin_env(f"{SMALL}/blueprint", "sha256:0000")
    assert make_twin_env(f"{SMALL}/blueprint", None, obs="paper").observation_space.shape == (10,)
