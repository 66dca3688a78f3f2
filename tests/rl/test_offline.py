"""Offline RL with d3rlpy: logged episodes are aligned and rewarded like the env, the behaviour policy is right,
names are checked, and a tiny run trains, saves, reloads and beats a random policy."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import UnknownNameError
from dtradar_rl.cli import main
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.mdp import GridMDP, reward_fn
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.offline.trainer import (
    ActionScores,
    OfflineConfig,
    OfflinePolicy,
    load_offline_policy,
    log_transitions,
    roll_behaviour,
    train_offline,
)

SMALL = "synthetic-12x8"
LOG = {"scene": SMALL, "num_envs": 16, "transitions": 3_000, "max_steps": 20, "shortest_prob": 0.3, "seed": 3}


@pytest.fixture(scope="module")
def small():
    return load_dataset(f"{SMALL}/blueprint")


def episodes_of(logged):
    """``(start, end)`` index ranges of the logged episodes (end exclusive)."""
    ends = np.flatnonzero(logged.terminals + logged.timeouts) + 1
    return list(zip(np.r_[0, ends[:-1]], ends))


def test_logged_episodes_are_contiguous_per_robot_and_end_in_exactly_one_terminal_or_timeout(small):
    cfg = OfflineConfig(**LOG)
    logged = roll_behaviour(small, cfg)
    n = len(logged)
    assert n >= cfg.transitions - 2 * cfg.num_envs
    assert all(len(a) == n for a in (logged.observations, logged.actions, logged.rewards, logged.terminals,
                                      logged.timeouts, logged.cells, logged.targets, logged.robots))
    assert not np.any((logged.terminals > 0) & (logged.timeouts > 0))           # never both on one step
    assert logged.terminals[-1] + logged.timeouts[-1] == 1                      # nothing unfinished at the end
    assert np.all(np.diff(logged.robots) >= 0)                                   # robot by robot
    assert logged.stats["truncated"] > 0 and logged.stats["reached"] > 0       # both kinds of ending occur
    mdp = GridMDP.from_dataset(small)
    table = build_observations(small, cfg.obs, Normalizer.fit(small))
    np.testing.assert_array_equal(logged.observations, table.observe(logged.cells, logged.targets))
    for s, e in episodes_of(logged):
        assert len(set(logged.robots[s:e])) == 1 and len(set(logged.targets[s:e])) == 1
        assert logged.terminals[s:e - 1].sum() + logged.timeouts[s:e - 1].sum() == 0  # one flag, on the last step
        # each step starts where the previous one led: the robot's stream is unbroken inside an episode
        np.testing.assert_array_equal(logged.cells[s + 1:e], mdp.next_cell[logged.cells[s:e - 1],
                                                                            logged.actions[s:e - 1]])
        assert bool(logged.terminals[e - 1]) == (mdp.next_cell[logged.cells[e - 1], logged.actions[e - 1]]
                                                 == logged.targets[e - 1])

    data = logged.to_mdp_dataset()                                                # d3rlpy splits the same way
    assert len(data.episodes) == logged.episodes == len(episodes_of(logged))
    assert sum(ep.size() for ep in data.episodes) == n
    for ep, (s, e) in zip(data.episodes, episodes_of(logged)):
        assert len(ep.observations) == len(ep.actions) == e - s
        assert ep.terminated == bool(logged.terminals[e - 1])


@pytest.mark.parametrize("reward", ["geodesic", "paper"])
def test_logged_rewards_equal_the_env_reward_function(small, reward):
    cfg = OfflineConfig(**dict(LOG, reward=reward, transitions=1_500))
    logged = roll_behaviour(small, cfg)
    data = log_transitions(small, cfg)
    mdp = GridMDP.from_dataset(small)
    c, a, t = logged.cells, logged.actions, logged.targets
    nxt, collision = mdp.next_cell[c, a], mdp.collides[c, a]
    targets, row = np.unique(t, return_inverse=True)
    dist = mdp.bfs_distances_many(targets)
    expected = reward_fn(reward, d2_after=mdp.d2(nxt, t), pot_before=dist[row, c], pot_after=dist[row, nxt],
                         collision=collision, reached=nxt == t, diag2=mdp.diag2)
    got = np.concatenate([ep.rewards[:, 0] for ep in data.episodes])
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    np.testing.assert_allclose(logged.rewards, expected, rtol=1e-6)


def test_noisy_shortest_with_p_1_reaches_every_target_along_a_shortest_path(small):
    logged = roll_behaviour(small, OfflineConfig(**dict(LOG, shortest_prob=1.0, max_steps=0)))
    mdp = GridMDP.from_dataset(small)
    assert logged.stats["truncated"] == 0 and not mdp.collides[logged.cells, logged.actions].any()
    last_of_robot = {int(r): i for i, r in enumerate(logged.robots)}
    finished = 0
    for s, e in episodes_of(logged):
        if e - 1 == last_of_robot[int(logged.robots[s])] and logged.timeouts[e - 1]:
            continue  # the robot's tail, cut when logging stopped
        assert logged.terminals[e - 1] == 1
        assert e - s == mdp.bfs_distances(int(logged.targets[s]))[logged.cells[s]]  # a shortest path
        finished += 1
    assert finished >= 100


def test_random_behaviour_takes_every_action_about_equally_often(small):
    logged = roll_behaviour(small, OfflineConfig(**dict(LOG, behaviour="random")))
    freq = np.bincount(logged.actions, minlength=4) / len(logged)
    assert np.all(np.abs(freq - 0.25) < 0.03)


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


def test_bc_trained_offline_saves_reloads_and_beats_a_random_policy(tmp_path, small, capsys):
    out = tmp_path / "bc"
    assert main(["offline", "--scene", SMALL, "--algorithm", "bc", "--transitions", "4000", "--num-envs", "32",
                 "--n-steps", "400", "--hidden", "64", "64", "--lr", "3e-3", "--shortest-prob", "0.8", "--pairs", "100", "--threads", "1",
                 "--out", str(out), "--no-verbose"]) == 0
    printed = capsys.readouterr().out
    assert f"bc: {SMALL}/blueprint -> {SMALL}/dynamic" in printed
    for name in ("model.d3", "config.json", "losses.csv", "dataset.h5", "transitions.npz", "results.json",
                 "results.md"):
        assert (out / name).exists(), name
    results = json.loads((out / "results.json").read_text())
    assert [(r["dataset"], r["shield"]) for r in results["results"]] == [
        (f"{SMALL}/blueprint", False), (f"{SMALL}/blueprint", True),
        (f"{SMALL}/dynamic", False), (f"{SMALL}/dynamic", True)]
    assert all(r["collisions"] == 0.0 for r in results["results"] if r["shield"])

    policy = load_offline_policy(out)
    assert policy.normalizer == Normalizer.fit(small) and policy.config.algorithm == "bc"
    trained, _ = evaluate(policy, small, pairs=200, seed=7, latency=False)
    chance = OfflinePolicy(q=None, config=policy.config, normalizer=policy.normalizer, obs_preset="neighbors",
                           meta={}, algo=RandomAlgo())
    random_, _ = evaluate(chance, small, pairs=200, seed=7, latency=False)
    assert trained.success_rate >= 0.7 and trained.success_rate > random_.success_rate + 0.3, (trained, random_)


@pytest.mark.parametrize("algorithm", ["cql", "bcq", "dqn", "ddqn", "nfq"])
def test_every_q_learning_algorithm_trains_saves_and_reloads_to_the_same_actions(tmp_path, small, algorithm):
    result = train_offline(OfflineConfig(**dict(LOG, algorithm=algorithm, n_steps=20, batch_size=32, hidden=(16,),
                                                eval_variants=(), save_dataset=False, threads=1, verbose=False,
                                                out=str(tmp_path))), dataset=small)
    assert result.n_steps == 20 and len(result.losses) == 10 and not result.rows
    reloaded = load_offline_policy(result.model)
    free = np.flatnonzero(~np.asarray(small.blocked).ravel())
    obs = torch.from_numpy(build_observations(small, "neighbors", reloaded.normalizer).observe(
        free, np.full_like(free, free[0])))
    np.testing.assert_array_equal(result.policy.act(obs).numpy(), reloaded.act(obs).numpy())
    assert ActionScores(reloaded.algo, algorithm)(obs).shape == (len(obs), 4)
    shielded = reloaded.act(obs, shield=True)
    flags = obs[:, reloaded.shield_columns()] > 0.5
    assert bool(flags.gather(1, shielded[:, None]).all())  # every free cell of the grid has an open neighbour


def test_a_saved_dataset_reloads_with_d3rlpy_and_trains_without_logging_again(tmp_path, small):
    import d3rlpy

    cfg = OfflineConfig(**dict(LOG, algorithm="dqn", n_steps=10, batch_size=16, hidden=(8,), eval_variants=(),
                               threads=1, verbose=False, out=str(tmp_path / "a")))
    first = train_offline(cfg, dataset=small)
    with open(tmp_path / "a" / "dataset.h5", "rb") as f:
        data = d3rlpy.dataset.ReplayBuffer.load(f, d3rlpy.dataset.InfiniteBuffer())
    assert data.transition_count == first.logged["transitions"]
    again = train_offline(dataclasses.replace(cfg, out=str(tmp_path / "b")), dataset=data)
    assert again.logged["source"] == "given" and not (tmp_path / "b" / "dataset.h5").exists()
    assert load_offline_policy(tmp_path / "b").meta["dataset"]["name"] == f"{SMALL}/blueprint"
    with pytest.raises(ConfigError, match="pass the --obs preset"):
        train_offline(dataclasses.replace(cfg, obs="goal"), dataset=data)
