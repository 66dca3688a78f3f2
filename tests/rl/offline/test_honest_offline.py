"""Offline agents on honest logs: the localisation filter replayed along every logged episode gives the learner the
same features the agent computes online, from the recorded observations alone; a run trains, saves, reloads as a
filtered policy and is evaluated with its sensing named."""

import dataclasses

import numpy as np
import pytest
import torch

from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.filter_senses import NAMES, FilteredPolicy, FilterSenses, map_agent
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.policy import load_offline_policy
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-10x8"
HONEST = LogConfig(
    scene=SMALL,
    behaviour="expert",
    steps=1500,
    num_envs=12,
    max_steps=30,
    seed=4,
    minari=False,
    verbose=False,
    sensing="radio",
)


@pytest.fixture()
def logged(root):
    return log_dataset(HONEST, load_dataset(f"{SMALL}/blueprint"))


class _Without:
    """A log whose ground-truth columns are scrambled: what the filter features may not depend on."""

    def __init__(self, logged):
        self._a = logged.arrays()

    def arrays(self):
        rng = np.random.default_rng(0)
        return {**self._a, "cell": rng.permutation(self._a["cell"]), "target": rng.permutation(self._a["target"])}


def test_the_filter_features_follow_from_the_recorded_observations_alone_and_match_the_online_agents(logged):
    agent = map_agent(SMALL, "radio", "realistic")
    senses = FilterSenses(logged, agent)
    np.testing.assert_array_equal(FilterSenses(_Without(logged), agent).features, senses.features)
    a = logged.arrays()
    ends = np.flatnonzero(a["terminated"] | a["truncated"])
    first = ends[0] + 1  # the second episode, fed to the policy's filter step by step as a robot would
    rows = np.arange(first, ends[1] + 1)
    scores = lambda x: torch.zeros((len(x), 4))  # noqa: E731
    seen = []

    class Algo:
        def predict(self, x):
            seen.append(x.copy())
            return np.zeros(len(x), np.int64)

    policy = FilteredPolicy(Algo(), scores, agent, OfflineConfig(scene=SMALL, sensing="radio"), {})
    for r in rows:
        policy.act(torch.tensor(a["obs"][r : r + 1]))
    np.testing.assert_allclose(np.concatenate(seen), senses.features[rows], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(senses.arrays(a)["next_obs"][rows[:-1]], senses.features[rows[1:]])
    assert senses.features.shape[1] == len(NAMES)


def test_an_offline_run_on_an_honest_log_reloads_as_a_filtered_policy_and_names_its_sensing(logged, tmp_path):
    cfg = OfflineConfig(
        scene=SMALL,
        sensing="radio",
        algorithm="bc",
        n_steps=200,
        pairs=40,
        eval_variants=("blueprint",),
        latency=False,
        out=str(tmp_path / "run"),
        verbose=False,
    )
    result = train_offline(cfg, logged)
    assert isinstance(result.policy, FilteredPolicy)
    assert [r["sensing"] for r in result.rows] == ["radio"]
    assert "radio" in result.markdown
    again = load_offline_policy(result.model)
    assert isinstance(again, FilteredPolicy) and again.config.sensing == "radio"


def test_honest_training_refuses_the_privileged_senses_and_relabelling():
    with pytest.raises(ConfigError, match="localisation filter"):
        OfflineConfig(scene=SMALL, sensing="radio", senses="memory").validate()
    with pytest.raises(ConfigError, match="relabelling is not built"):
        OfflineConfig(scene=SMALL, sensing="radio", relabel="future").validate()
    with pytest.raises(ConfigError, match="--sensing radio"):
        dataclasses.replace(OfflineConfig(scene=SMALL), senses="filter").validate()
