"""Dataset families named like D4RL's (random, expert, medium, medium-replay, mixed): each logs under its name with
its normalised score in the card; medium stops near its target and is reproducible; medium-replay is exactly the
medium run's replay buffer."""

import dataclasses

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import CorruptDatasetError
from dtradar_data.core.files import sha256_file
from dtradar_data.store.logged import arrays
from dtradar_rl.agents.checkpoints import CHECKPOINT_FORMAT, read_checkpoint
from dtradar_rl.cli import main
from dtradar_rl.offline import medium_agent as M
from dtradar_rl.offline.behaviours import FAMILIES, MEDIUM_TARGET, OGBENCH_FAMILIES
from dtradar_rl.offline.collection import replay
from dtradar_rl.offline.logged import LogConfig, log_dataset, log_families
from dtradar_rl.offline.medium_agent import medium_agent
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.replay import replay_transitions

TINY = "synthetic-8x6"
#: small enough for seconds: 32 robots, a 40k-step budget the tiny twin's medium agent stops well inside
SETTINGS = dict(scene=TINY, steps=3_000, num_envs=32, medium_budget=40_000, minari=False, verbose=False, seed=0)


@pytest.fixture(scope="module")
def tiny():
    return load_dataset(f"{TINY}/blueprint")


@pytest.fixture(scope="module")
def families(tiny, tmp_path_factory):
    """The eight families logged once on the tiny twin, in a data root of their own."""
    with pytest.MonkeyPatch.context() as mp:
        root = tmp_path_factory.mktemp("families") / "root"
        mp.setenv("DTRADAR_DATA_ROOT", str(root))
        out = log_families(LogConfig(behaviour="all", **SETTINGS), tiny)
        agent = medium_agent(LogConfig(behaviour="medium", **SETTINGS), tiny, say=lambda *a: None)
        yield out, agent, root


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_all_logs_every_family_under_its_name_with_its_normalised_score_in_the_card(families):
    out, _, _ = families
    assert list(out) == [*FAMILIES, *OGBENCH_FAMILIES]
    for family, logged in out.items():
        assert logged.name == f"{TINY}/blueprint/{family}"
        assert logged.meta["family"] == family
        score = logged.meta["score"]
        card = (logged.path / "README.md").read_text()
        assert "## Normalised score" in card
        assert f"{score['episodes']['normalized']:.1f} (its logged episodes)" in card
        if family == "medium-replay":
            assert score["policy"] is None  # a replay buffer is no single policy
        else:
            assert f"**{score['policy']['normalized']:.1f}** (the behaviour rolled out" in card
        assert score["references"]["expert"] == 1.0


def test_the_families_rank_random_below_medium_below_expert(families):
    out, _, _ = families
    pol = {f: out[f].meta["score"]["policy"]["normalized"] for f in ("random", "medium", "expert", "mixed")}
    assert abs(pol["random"]) < 15
    assert pol["random"] < pol["medium"] < pol["expert"]
    assert 85 < pol["expert"] < 100  # 5 % random moves: a little below the noise-free expert's 100
    assert pol["random"] < pol["mixed"] < pol["expert"]


def test_medium_stops_at_the_first_evaluation_at_its_target(families):
    out, agent, _ = families
    rec = agent.record
    scores = [h["score"] for h in rec["history"]]
    assert all(s < MEDIUM_TARGET for s in scores[:-1]) and scores[-1] >= MEDIUM_TARGET
    assert MEDIUM_TARGET <= rec["score"] <= MEDIUM_TARGET + 25  # a tiny twin learns in jumps: a loose tolerance
    assert rec["stopped_at_env_steps"] < SETTINGS["medium_budget"]
    # the card's rolled-out medium behaviour is the very agent the stop measured
    medium = out["medium"].meta
    assert medium["score"]["policy"]["normalized"] == pytest.approx(rec["score"], abs=1.0)
    assert medium["medium_agent"]["checkpoint_sha256"] == sha256_file(agent.checkpoint)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_medium_is_reproducible_with_its_seed_and_changes_with_another(families, tiny, tmp_path, monkeypatch):
    _, agent, _ = families

    def weights(a):
        return read_checkpoint(a.checkpoint, (CHECKPOINT_FORMAT,), what="model.pt")["q"]

    again = {}
    for seed in (0, 1):
        monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / f"seed{seed}"))
        cfg = LogConfig(behaviour="medium", **{**SETTINGS, "seed": seed})
        again[seed] = medium_agent(cfg, tiny, say=lambda *a: None)
    rec, rec0 = agent.record, again[0].record
    assert rec0["key"] == rec["key"] and rec0["stopped_at_env_steps"] == rec["stopped_at_env_steps"]
    assert [(h["env_steps"], h["score"]) for h in rec0["history"]] == [
        (h["env_steps"], h["score"]) for h in rec["history"]
    ]
    w, w0, w1 = weights(agent), weights(again[0]), weights(again[1])
    assert all(torch.equal(w[k], w0[k]) for k in w)  # bit for bit
    assert again[1].record["key"] != rec["key"] and not all(torch.equal(w[k], w1[k]) for k in w)


def test_medium_replay_holds_exactly_the_medium_runs_collected_transitions(families):
    out, agent, _ = families
    buf = replay_transitions(read_checkpoint(agent.last, (CHECKPOINT_FORMAT,), what="last.pt")["replay"])
    a = arrays(out["medium-replay"].table)
    n = SETTINGS["num_envs"]
    assert len(a["action"]) == len(buf["action"]) == agent.record["stopped_at_env_steps"]
    # the table is robot by robot; the buffer step by step (n robots per step)
    horizon = len(a["action"]) // n
    order = np.arange(len(a["action"])).reshape(n, horizon).T.reshape(-1)
    for k in ("obs", "action", "reward", "next_obs", "terminated"):
        np.testing.assert_array_equal(a[k][order], buf[k], err_msg=k)
    assert out["medium-replay"].meta["inputs"]["steps"] == 0  # --steps does not apply


def test_replaying_a_buffer_on_other_settings_is_refused(families, tiny):
    _, agent, _ = families
    buf = read_checkpoint(agent.last, (CHECKPOINT_FORMAT,), what="last.pt")["replay"]
    with pytest.raises(CorruptDatasetError, match="differs from its run"):
        replay(tiny, buf, num_envs=SETTINGS["num_envs"], seed=5)


def test_logging_medium_again_reuses_the_cached_agent(families, tiny, monkeypatch):
    _, agent, root = families
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(root))

    def boom(*a, **k):
        raise AssertionError("trained again")

    monkeypatch.setattr(M, "_train_medium", boom)
    logged = log_dataset(LogConfig(behaviour="medium", **{**SETTINGS, "steps": 1_000}), tiny)
    assert logged.meta["medium_agent"]["key"] == agent.record["key"]
    assert logged.meta["inputs"]["steps"] == 1_000


def test_mixed_splits_the_robots_between_random_medium_and_expert(families):
    out, _, _ = families
    a = arrays(out["mixed"].table)
    np.testing.assert_array_equal(a["component"], a["robot"] % 3)
    assert out["mixed"].meta["behaviour"]["components"] == ["random", "medium", "expert"]


def test_a_medium_agent_that_misses_its_target_is_an_error(tiny, root):
    cfg = LogConfig(behaviour="medium", **{**SETTINGS, "medium_budget": 4_096, "medium_target": 99.0})
    with pytest.raises(ConfigError, match="short of the target 99"):
        medium_agent(cfg, tiny, say=lambda *a: None)


def test_all_takes_no_name_and_the_families_take_no_checkpoint(root):
    with pytest.raises(ConfigError, match="--name names one dataset"):
        LogConfig(behaviour="all", name="x").validate()
    for f in FAMILIES:
        LogConfig(behaviour=f).validate()  # none needs --checkpoint
    assert dataclasses.replace(LogConfig(), behaviour="medium-replay", steps=0).validate()
    assert main(["log", "--scene", TINY, "--behaviour", "all", "--name", "x"]) == 2


def test_the_store_knows_every_behaviour_kind_and_relogs_a_medium_family_with_its_recipe():
    from dtradar_data.core.ids import parse_logged_id
    from dtradar_data.store.logged.hints import BEHAVIOUR_KINDS, log_commands
    from dtradar_rl.offline.behaviours import BEHAVIOURS

    assert set(BEHAVIOUR_KINDS) == set(BEHAVIOURS)  # dtradar_data cannot import torch: a copy, kept equal here
    beh = {"kind": "medium", "medium": {"target": 40.0, "budget": 5000}}
    python, make = log_commands(parse_logged_id("cubicle/blueprint/medium"), {"inputs": {"behaviour": beh}})
    assert "--behaviour medium" in python and "--medium-target 40.0 --medium-budget 5000" in python
    assert "BEHAVIOUR=medium" in make
