import numpy as np
import pytest

from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.evaluation.evaluate import evaluate, metrics_from_rollouts, rollout
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset


@pytest.mark.parametrize("variant", ["blueprint", "dynamic"])
def test_the_baseline_planner_reaches_every_reachable_target_when_its_map_is_the_twin_itself(variant):
    ds = load_dataset(f"synthetic-12x8/{variant}")
    mdp = GridMDP.from_dataset(ds)
    cells = mdp.pair_cells()
    rng = np.random.default_rng(0)  # every target, from three random starts each
    pairs = np.array(
        [(s, t) for t in cells for s in rng.choice([c for c in cells if c != t and mdp.connected(c, t)], 3)]
    )
    roll = rollout(FingerprintPlanner(ds), ds, pairs)
    m = metrics_from_rollouts(roll)
    assert m.success_rate == 1.0 and m.spl == pytest.approx(1.0) and m.collisions == 0


def test_on_a_changed_twin_the_planner_senses_new_obstacles_and_replans_around_them():
    bp, dyn = load_dataset("synthetic-16x10/blueprint"), load_dataset("synthetic-16x10/dynamic")
    metrics, _ = evaluate(FingerprintPlanner(bp), dyn, pairs=100, latency=True)
    assert metrics.success_rate > 0.9 and metrics.latency_ms > 0


def test_one_robots_compiled_search_and_the_batched_search_give_the_same_distances():
    import torch

    planner = FingerprintPlanner(load_dataset("synthetic-16x10/blueprint"))
    mdp, rng = planner.mdp, np.random.default_rng(0)
    free = np.flatnonzero(mdp.free)
    # targets on free cells and on blocked ones (a dynamic twin's target may sit where the blueprint has an object)
    targets = np.concatenate([rng.choice(free, 10), np.flatnonzero(mdp.blocked.ravel())[:3]])
    extra = np.zeros((targets.size, mdp.num_cells), bool)
    for i, t in enumerate(targets):
        extra[i, rng.choice(free, 6)] = True
        extra[i, t] = False
    t, ex = torch.as_tensor(targets), torch.as_tensor(extra)
    each, batched = planner.search.each(t, ex), planner.search.batched(t, ex)
    assert torch.equal(each, batched) and (each >= 0).sum() > targets.size
