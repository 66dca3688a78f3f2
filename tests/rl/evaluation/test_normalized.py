"""The normalised score, defined once: 0 at the uniformly random policy, 100 at the breadth-first expert, linear in
between, on a twin's seeded evaluation pairs."""

import numpy as np
import pytest

from dtradar_rl.evaluation import normalized as N
from dtradar_rl.evaluation.normalized import (
    logged_episodes_spl,
    normalized,
    policy_score,
    reference_policy,
    reference_scores,
)
from dtradar_rl.offline.behaviours import BehaviourSpec, behaviour_policy
from dtradar_rl.offline.collection import roll
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset

PAIRS = 200


@pytest.fixture(scope="module")
def tiny():
    return load_dataset("synthetic-8x6/blueprint")


@pytest.fixture(scope="module")
def small():
    return load_dataset("synthetic-12x8/blueprint")


def test_the_normalised_score_is_0_for_the_random_reference_and_100_for_the_expert_by_construction(small):
    refs = reference_scores(small, pairs=PAIRS, seed=7)
    assert refs["expert"] == 1.0  # measured: every pair walked along a shortest path
    assert 0 < refs["random"] < 0.5  # a random walk sometimes stumbles onto its target
    assert normalized(refs["random"], refs) == 0.0
    assert normalized(refs["expert"], refs) == 100.0
    # the references themselves, rolled out again on the same pairs with the same seed, score exactly 0 and 100
    assert policy_score(reference_policy("random", 7), small, pairs=PAIRS, seed=7)["normalized"] == 0.0
    assert policy_score(reference_policy("expert", 7), small, pairs=PAIRS, seed=7)["normalized"] == 100.0


def test_the_normalised_score_is_linear_and_increasing_between_the_references():
    refs = {"random": 0.2, "expert": 1.0}
    values = np.linspace(0, 1, 11)
    scores = [normalized(v, refs) for v in values]
    assert np.all(np.diff(scores) > 0)
    assert normalized(0.6, refs) == pytest.approx(50.0)
    with pytest.raises(ConfigError, match="does not exceed"):
        normalized(0.5, {"random": 0.4, "expert": 0.4})


def test_behaviours_closer_to_the_expert_score_higher(small):
    """noisy-shortest with a growing probability of the shortest move climbs from about 0 to exactly 100."""
    scores = []
    for p in (0.0, 0.4, 0.8, 1.0):
        bp = behaviour_policy(BehaviourSpec("noisy-shortest", shortest_prob=p), small, seed=1)
        scores.append(policy_score(bp, small, pairs=PAIRS, seed=7)["normalized"])
    assert np.all(np.diff(scores) > 0), scores
    assert abs(scores[0]) < 10 and scores[-1] == 100.0


def test_the_expert_reference_is_measured_so_a_step_limit_too_short_shows(small):
    refs = reference_scores(small, pairs=PAIRS, seed=7, max_steps=3)
    assert refs["expert"] < 1.0  # pairs farther than 3 moves fail


def test_reference_scores_are_cached_per_twin_pairs_and_seed(small, tiny, monkeypatch):
    first = reference_scores(small, pairs=PAIRS, seed=7)

    def boom(*a, **k):
        raise AssertionError("rolled out again")

    monkeypatch.setattr(N, "rollout", boom)
    assert reference_scores(small, pairs=PAIRS, seed=7) == first
    for other in (dict(pairs=PAIRS, seed=8), dict(pairs=PAIRS + 1, seed=7)):
        with pytest.raises(AssertionError, match="rolled out again"):
            reference_scores(small, **other)
    with pytest.raises(AssertionError, match="rolled out again"):  # another twin is not the cached one
        reference_scores(tiny, pairs=PAIRS, seed=7)


def test_the_spl_of_logged_episodes_counts_only_episodes_that_could_finish(small):
    def spl_of(spec, steps=2_000, num_envs=8, max_steps=30):
        c = roll(small, spec, steps=steps, num_envs=num_envs, max_steps=max_steps, seed=2).columns
        cols = {k: c[k] for k in ("episode", "robot", "cell", "action", "target", "terminated")}
        return c, logged_episodes_spl(small, **cols, max_steps=max_steps)

    c, expert = spl_of(BehaviourSpec("noisy-shortest", shortest_prob=1.0))
    assert expert["spl"] == 1.0 and expert["success_rate"] == 1.0
    # exactly the episodes that started at least max_steps before the end of their robot's 250-step stream
    first = np.r_[True, c["episode"][1:] != c["episode"][:-1]]
    pos = np.arange(len(c["robot"])) % 250
    assert expert["episodes"] == int((first & (pos + 30 <= 250)).sum())
    _, rand = spl_of(BehaviourSpec("random"))
    assert rand["spl"] < 0.3
    assert expert["selection"] == rand["selection"] == "started-early"
    # 20 steps per robot, under the limit of 30: no episode started early enough, the finished ones count (flagged)
    c, short = spl_of(BehaviourSpec("noisy-shortest", shortest_prob=0.5), steps=160, max_steps=30)
    assert short["selection"] == "finished" and short["episodes"] == int(c["terminated"].sum()) > 0
    _, none = spl_of(BehaviourSpec("random"), steps=16, max_steps=30)  # 2 steps per robot: no episode finished
    assert none["episodes"] == 0 and np.isnan(none["spl"])
