"""Offline RL with d3rlpy: names are checked, a tiny run trains on a named logged dataset, saves, reloads and beats
a random policy, and every result names the logged version it came from."""

import dataclasses
import json

import numpy as np
import pytest

from dtradar_data.core.errors import SchemaMismatchError, UnknownNameError
from dtradar_rl.cli import main
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.policy import ActionScores, OfflinePolicy, load_offline_policy
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"
LOG = {"scene": SMALL, "num_envs": 16, "transitions": 3_000, "max_steps": 20, "shortest_prob": 0.3, "seed": 3}


@pytest.fixture(scope="module")
def small():
    return load_dataset(f"{SMALL}/blueprint")


def test_unknown_algorithm_or_behaviour_name_is_a_typed_error_with_a_suggestion(capsys):
    with pytest.raises(UnknownNameError, match="did you mean 'cql'"):
        OfflineConfig(algorithm="cq").validate()
    with pytest.raises(UnknownNameError, match="did you mean 'random'"):
        OfflineConfig(behaviour="randon").validate()
    assert main(["offline", "--scene", SMALL, "--algorithm", "bcx"]) == 2
    assert "unknown offline algorithm 'bcx'" in capsys.readouterr().err


class RandomAlgo:
    """Stands in for a d3rlpy algorithm: uniformly random moves."""

    def __init__(self, seed=0):
        self.rng = np.random.default_rng(seed)

    def predict(self, x):
        return self.rng.integers(0, 4, len(x))


def test_bc_trained_offline_saves_reloads_and_beats_a_random_policy(root, tmp_path, small, capsys):
    out = tmp_path / "bc"
    assert (
        main(
            [
                "offline",
                "--scene",
                SMALL,
                "--algorithm",
                "bc",
                "--transitions",
                "4000",
                "--num-envs",
                "32",
                "--n-steps",
                "400",
                "--hidden",
                "64",
                "64",
                "--lr",
                "3e-3",
                "--shortest-prob",
                "0.8",
                "--pairs",
                "100",
                "--threads",
                "1",
                "--out",
                str(out),
                "--no-verbose",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert f"bc: {SMALL}/blueprint -> {SMALL}/dynamic" in printed
    for name in ("model.d3", "config.json", "losses.csv", "results.json", "results.md"):
        assert (out / name).exists(), name
    results = json.loads((out / "results.json").read_text())
    assert [(r["dataset"], r["shield"]) for r in results["results"]] == [
        (f"{SMALL}/blueprint", False),
        (f"{SMALL}/blueprint", True),
        (f"{SMALL}/dynamic", False),
        (f"{SMALL}/dynamic", True),
    ]
    assert all(r["collisions"] == 0.0 for r in results["results"] if r["shield"])

    policy = load_offline_policy(out)
    assert policy.normalizer == Normalizer.fit(small) and policy.config.algorithm == "bc"
    trained, _ = evaluate(policy, small, pairs=200, seed=7, latency=False)
    chance = OfflinePolicy(
        q=None, config=policy.config, normalizer=policy.normalizer, obs_preset="neighbors", meta={}, algo=RandomAlgo()
    )
    random_, _ = evaluate(chance, small, pairs=200, seed=7, latency=False)
    assert trained.success_rate >= 0.7 and trained.success_rate > random_.success_rate + 0.3, (trained, random_)


@pytest.mark.parametrize("algorithm", ["cql", "bcq", "dqn", "ddqn", "nfq"])
def test_every_q_learning_algorithm_trains_saves_and_reloads_to_the_same_actions(root, tmp_path, small, algorithm):
    result = train_offline(
        OfflineConfig(
            **dict(
                LOG,
                algorithm=algorithm,
                n_steps=20,
                batch_size=32,
                hidden=(16,),
                eval_variants=(),
                threads=1,
                verbose=False,
                out=str(tmp_path),
            )
        ),
        dataset=small,
    )
    assert result.n_steps == 20 and len(result.losses) == 10 and not result.rows
    reloaded = load_offline_policy(result.model)
    free = np.flatnonzero(~np.asarray(small.blocked).ravel())
    # observed as the policy observes (the Q-learners' default senses add the memory window)
    obs = reloaded.env_for(small, len(free), seed=0).reset()
    np.testing.assert_array_equal(result.policy.act(obs).numpy(), reloaded.act(obs).numpy())
    assert ActionScores(reloaded.algo, algorithm)(obs).shape == (len(obs), 4)
    shielded = reloaded.act(obs, shield=True)
    flags = obs[:, reloaded.shield_columns()] > 0.5
    assert bool(flags.gather(1, shielded[:, None]).all())  # every free cell of the grid has an open neighbour


def tiny_dqn(out) -> OfflineConfig:
    """Offline DQN for ten updates, no evaluation: enough to see which logged dataset a run trains on."""
    return OfflineConfig(
        **dict(
            LOG,
            algorithm="dqn",
            n_steps=10,
            batch_size=16,
            hidden=(8,),
            eval_variants=(),
            threads=1,
            verbose=False,
            out=str(out),
        )
    )


def test_without_logged_the_trainer_logs_a_named_dataset_once_and_every_result_names_its_version(root, tmp_path, small):
    from dtradar_data.store.logged import local_versions, parse_logged_id

    cfg = tiny_dqn(tmp_path / "a")
    first = train_offline(cfg, dataset=small)
    lid = parse_logged_id(f"{SMALL}/blueprint/noisy-shortest")
    (version,) = local_versions(lid)
    assert first.logged["source"] == f"{lid.name}@{version}"
    meta = json.loads((tmp_path / "a" / "config.json").read_text())
    assert meta["logged"]["name"] == lid.name and meta["logged"]["version"] == version
    again = train_offline(dataclasses.replace(cfg, out=str(tmp_path / "b")), dataset=small)
    assert local_versions(lid) == [version] and again.logged["source"] == first.logged["source"]  # reused
    by_name = train_offline(
        dataclasses.replace(cfg, out=str(tmp_path / "c"), logged=f"{lid.name}@{version}"), dataset=small
    )
    assert by_name.logged["source"] == first.logged["source"]
    assert load_offline_policy(tmp_path / "c").meta["dataset"]["name"] == f"{SMALL}/blueprint"
    other = train_offline(dataclasses.replace(cfg, out=str(tmp_path / "d"), seed=4), dataset=small)
    assert len(local_versions(lid)) == 2 and other.logged["source"] != first.logged["source"]  # another seed


def test_a_log_with_another_preset_is_refused_before_training(root, tmp_path, small):
    cfg = tiny_dqn(tmp_path / "a")
    first = train_offline(cfg, dataset=small)
    with pytest.raises(SchemaMismatchError, match="preset"):
        train_offline(dataclasses.replace(cfg, obs="goal", logged=first.logged["source"]), dataset=small)
