"""The mover events split: every mover collision and hit of a rollout is counted once per kind, the splits add up
to it, and the counts match the evaluation's."""

import pytest
import torch

from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.evaluation.evaluate import rollout, sample_eval_pairs
from dtradar_rl.experiments.mover_events import mover_events
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for


class Straight(QNetwork):
    """Always X+ then Y+ (a policy that walks into whatever comes), with a wait it never takes."""

    def __init__(self):
        super().__init__(8, (1,), n_actions=5)

    def forward(self, x):
        return torch.tensor([0.0, 3.0, 1.0, 2.0, -1.0]).expand(x.shape[0], 5)


def test_the_splits_add_up_to_the_evaluations_mover_collisions_and_hits():
    ds = load_dataset("synthetic-moving-12x8/blueprint")
    cfg = config_for(
        scene="synthetic-moving-12x8",
        wait_action=True,
        sense_radius=2,
        memory_radius=0,
        memory_visits=False,
        escape_after=0,
    )
    policy = Policy(Straight(), cfg, Normalizer.fit(ds), "neighbors", {})
    events = mover_events(policy, ds, pairs=60, seed=1)
    r = rollout(policy, ds, sample_eval_pairs(ds, 60, 1))
    both = events.get("collision+hit", 0.0)
    assert events.get("collision", 0.0) + both == pytest.approx(r.mover_collisions.mean())
    assert events.get("hit", 0.0) + both == pytest.approx(r.mover_hits.mean())
    for kind in ("collision", "hit", "collision+hit"):
        total = events.get(kind, 0.0)
        assert sum(events.get(f"{kind}|avoidable={v}", 0.0) for v in (True, False)) == pytest.approx(total)
        assert sum(events.get(f"{kind}|in_sight={v}", 0.0) for v in (True, False)) == pytest.approx(total)
    assert events.get("collision", 0.0) + events.get("hit", 0.0) + both > 0  # the walk did meet movers
