"""The one rollout engine: logged episodes are contiguous per robot and end in exactly one flag, rewards equal the
env's reward function, and the behaviours act as specified."""

import numpy as np
import pytest

from dtradar_rl.offline.behaviours import BehaviourSpec
from dtradar_rl.offline.collection import roll
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.rewards import reward_fn
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"
LOG = {"steps": 3_000, "num_envs": 16, "max_steps": 20, "seed": 3}


@pytest.fixture(scope="module")
def small():
    return load_dataset(f"{SMALL}/blueprint")


def episodes_of(c):
    """``(start, end)`` index ranges of the logged episodes (end exclusive)."""
    ends = np.flatnonzero(c["terminated"] | c["truncated"]) + 1
    return list(zip(np.r_[0, ends[:-1]], ends))


def test_logged_episodes_are_contiguous_per_robot_and_end_in_exactly_one_terminal_or_truncation(small):
    r = roll(small, BehaviourSpec("noisy-shortest", shortest_prob=0.3), **LOG)
    c = r.columns
    n = len(c["action"])
    assert n >= LOG["steps"] and n == r.stats["steps"]  # nothing dropped
    assert not np.any(c["terminated"] & c["truncated"])  # never both on one step
    assert c["terminated"][-1] or c["truncated"][-1]  # nothing unfinished at the end
    assert np.all(np.diff(c["robot"]) >= 0)  # robot by robot
    assert r.stats["terminated"] > 0 and r.stats["truncated_step_limit"] > 0  # both kinds of ending occur
    mdp = GridMDP.from_dataset(small)
    table = build_observations(small, "neighbors", Normalizer.fit(small))
    np.testing.assert_array_equal(c["obs"], table.observe(c["cell"], c["target"]))
    for s, e in episodes_of(c):
        assert len(set(c["robot"][s:e])) == 1 and len(set(c["target"][s:e])) == 1
        assert not (c["terminated"][s : e - 1] | c["truncated"][s : e - 1]).any()  # one flag, on the last step
        # each step starts where the previous one led: the robot's stream is unbroken inside an episode
        np.testing.assert_array_equal(c["cell"][s + 1 : e], mdp.next_cell[c["cell"][s : e - 1], c["action"][s : e - 1]])
        np.testing.assert_array_equal(c["obs"][s + 1 : e], c["next_obs"][s : e - 1])
        assert bool(c["terminated"][e - 1]) == (
            mdp.next_cell[c["cell"][e - 1], c["action"][e - 1]] == c["target"][e - 1]
        )
        np.testing.assert_array_equal(c["step"][s:e], np.arange(e - s))


@pytest.mark.parametrize("reward", ["geodesic", "paper"])
def test_logged_rewards_equal_the_env_reward_function(small, reward):
    c = roll(
        small, BehaviourSpec("noisy-shortest", shortest_prob=0.3), **{**LOG, "steps": 1_500}, reward=reward
    ).columns
    mdp = GridMDP.from_dataset(small)
    cell, a, t = c["cell"], c["action"], c["target"]
    nxt, collision = mdp.next_cell[cell, a], mdp.collides[cell, a]
    targets, row = np.unique(t, return_inverse=True)
    dist = mdp.bfs_distances_many(targets)
    expected = reward_fn(
        reward,
        d2_after=mdp.d2(nxt, t),
        pot_before=dist[row, cell],
        pot_after=dist[row, nxt],
        collision=collision,
        reached=nxt == t,
        diag2=mdp.diag2,
    )
    np.testing.assert_allclose(c["reward"], expected, rtol=1e-6)


def test_noisy_shortest_with_p_1_reaches_every_target_along_a_shortest_path(small):
    r = roll(small, BehaviourSpec("noisy-shortest", shortest_prob=1.0), **{**LOG, "max_steps": None})
    c = r.columns
    mdp = GridMDP.from_dataset(small)
    assert r.stats["truncated_step_limit"] == 0 and not mdp.collides[c["cell"], c["action"]].any()
    last_of_robot = {int(robot): i for i, robot in enumerate(c["robot"])}
    finished = 0
    for s, e in episodes_of(c):
        if e - 1 == last_of_robot[int(c["robot"][s])] and c["truncated"][e - 1]:
            continue  # the robot's tail, cut when logging stopped
        assert c["terminated"][e - 1]
        assert e - s == mdp.bfs_distances(int(c["target"][s]))[c["cell"][s]]  # a shortest path
        finished += 1
    assert finished >= 100


def test_random_behaviour_takes_every_action_about_equally_often(small):
    c = roll(small, BehaviourSpec("random"), **LOG).columns
    freq = np.bincount(c["action"], minlength=4) / len(c["action"])
    assert np.all(np.abs(freq - 0.25) < 0.03)
