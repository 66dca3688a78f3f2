"""Evaluation on a moving twin: (start, target, t0) episodes, SPL against the space-time shortest path, wall
collisions, mover collisions and mover hits per episode, and the classical planner among movers."""

import numpy as np
import pytest
import torch

from dtradar_data.pipeline.synthetic import Mover, synthetic_moving_dataset
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.evaluation.evaluate import (
    MOVING_METRICS,
    evaluate,
    markdown_table,
    metrics_from_rollouts,
    rollout,
    sample_eval_pairs,
)
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset

X_PLUS, Y_MINUS = 1, 2

# The corridor of the space-time test, as a dataset: a mover steps between the corridor (3, 1) at odd snapshots
# and its niche (3, 0) at even ones. From (0, 1) at snapshot 0 the robot reaches (3, 1) at snapshot 3 (taken): it
# waits one step and arrives at (6, 1) after 7 steps; the static shortest path is 6.
WALLS = np.array(
    [
        [1, 1, 1, 0, 1, 1, 1],
        [0, 0, 0, 0, 0, 0, 0],
        [0, 1, 1, 1, 1, 1, 0],
        [0, 0, 0, 0, 0, 0, 0],
    ],
    bool,
)


@pytest.fixture(scope="module")
def corridor():
    return synthetic_moving_dataset(7, 4, movers=[Mover("walker", (3, 0), "y", 2)], blocked=WALLS, name="corridor/x")


class Scripted:
    """The part of a Policy that :func:`rollout` uses: the same action for every robot at every step."""

    obs_preset = "goal"

    def __init__(self, action: int):
        self.action = action

    def env_for(self, ds, num_envs, **kwargs):
        return BatchedNavEnv.from_dataset(ds, num_envs, obs="goal", **kwargs)

    def act(self, obs, shield=False):
        return torch.full((obs.shape[0],), self.action, dtype=torch.long)


def test_evaluation_pairs_of_a_moving_twin_carry_their_start_snapshot():
    ds = load_dataset("synthetic-moving-12x8/blueprint")
    pairs = sample_eval_pairs(ds, 30, seed=5)
    assert pairs.shape == (30, 3)
    np.testing.assert_array_equal(pairs, sample_eval_pairs(ds, 30, seed=5))
    assert sample_eval_pairs(load_dataset("synthetic-12x8/blueprint"), 30, seed=5).shape == (30, 2)


def test_spl_compares_steps_with_the_space_time_shortest_path(corridor):
    mdp = GridMDP.from_dataset(corridor)
    s, t = mdp.cell(0, 1), mdp.cell(6, 1)
    roll = rollout(Scripted(X_PLUS), corridor, np.array([[s, t, 0], [s, t, 1]]))
    # t0 = 0: bumps into the mover once (a wait), 7 steps = the space-time optimum; t0 = 1: straight through, 6
    assert roll.shortest.tolist() == [7, 6] and roll.steps.tolist() == [7, 6]
    assert roll.mover_collisions.tolist() == [1, 0] and roll.wall_collisions.tolist() == [0, 0]
    assert roll.mover_hits.tolist() == [0, 0] and roll.collisions.tolist() == [1, 0]
    m = metrics_from_rollouts(roll)
    assert m.success_rate == 1.0 and m.spl == pytest.approx(1.0)
    assert (m.mover_collisions, m.wall_collisions, m.mover_hits) == (0.5, 0.0, 0.0)
    assert m.path_length == 6.0  # cells travelled; SPL counts the step spent waiting


def test_a_robot_standing_in_the_movers_way_is_hit_and_counted_apart(corridor):
    mdp = GridMDP.from_dataset(corridor)
    # on (3, 1) at snapshot 0, pushing into the niche: the mover comes out of it onto the robot (a swap refused and
    # a hit), then goes back in (a mover collision); four steps
    roll = rollout(Scripted(Y_MINUS), corridor, np.array([[mdp.cell(3, 1), mdp.cell(6, 1), 0]]), max_steps=4)
    assert roll.mover_collisions.tolist() == [4] and roll.mover_hits.tolist() == [2]
    assert roll.wall_collisions.tolist() == [0] and not roll.success[0]
    m = metrics_from_rollouts(roll)
    assert m.spl == 0.0 and m.mover_hits == 2.0 and m.collisions == 4.0


def test_wall_collisions_are_told_from_mover_collisions(corridor):
    mdp = GridMDP.from_dataset(corridor)
    roll = rollout(Scripted(Y_MINUS), corridor, np.array([[mdp.cell(0, 1), mdp.cell(6, 1)]]), max_steps=5)
    assert roll.t0.tolist() == [0]  # no t0 given: the first snapshot in which the start is free
    assert roll.wall_collisions.tolist() == [5] and roll.mover_collisions.tolist() == [0]


def test_a_static_twins_metrics_and_table_are_unchanged():
    ds = load_dataset("synthetic-12x8/blueprint")
    m, roll = evaluate(FingerprintPlanner(ds), ds, pairs=20, latency=False)
    assert roll.t0 is None and roll.mover_hits is None
    assert not set(MOVING_METRICS) & set(m.to_dict())
    assert "mover" not in markdown_table([{"case": "static", **m.to_dict()}])


def test_the_planner_replanning_on_the_current_snapshot_reaches_its_targets_among_movers():
    ds = load_dataset("synthetic-moving-12x8/blueprint")
    honest, _ = evaluate(FingerprintPlanner(ds), ds, pairs=100, latency=False)  # one-shot localisation from radio
    assert honest.success_rate >= 0.9 and honest.spl > 0.75
    # the neighbours' radio of the twin (privileged) localises it better and replans the same way
    m, roll = evaluate(FingerprintPlanner(ds, sensing="privileged"), ds, pairs=100, latency=False)
    assert m.success_rate >= 0.95 and m.spl > 0.8
    assert roll.t0 is not None and (roll.shortest > 0).all()
    assert m.mover_collisions is not None and m.mover_collisions + m.wall_collisions == pytest.approx(m.collisions)
    row = {"case": "planner -> moving", **m.to_dict()}
    assert set(MOVING_METRICS) <= set(row)
    assert "mover collisions/ep | mover hits/ep" in markdown_table([row])
    # planned on the static blueprint instead of the moving twin's background: the same map and fingerprints
    blueprint = load_dataset("synthetic-12x8/blueprint")
    m_bp, _ = evaluate(FingerprintPlanner(blueprint, sensing="privileged"), ds, pairs=100, latency=False)
    assert m_bp.success_rate >= 0.95


@pytest.mark.slow  # trains, evaluates and draws an animation: ~9 s (make test-all)
def test_make_eval_takes_the_moving_twin_and_draws_its_episodes_as_an_animation(tmp_path):
    from PIL import Image

    from dtradar_data.core.errors import UnknownNameError
    from dtradar_rl.evaluation.jobs import EvalConfig
    from dtradar_rl.viz.plots import plot_moving_paths

    assert EvalConfig(variants=("blueprint", "dynamic", "moving")).validate().variants[-1] == "moving"
    with pytest.raises(UnknownNameError, match="did you mean .moving."):
        EvalConfig(variants=("movin",)).validate()
    ds = load_dataset("synthetic-moving-12x8/blueprint")
    pairs = sample_eval_pairs(ds, 2, 0)
    r = rollout(FingerprintPlanner(ds), ds, pairs)
    gif = plot_moving_paths(ds, r.paths, r.t0, tmp_path / "paths_moving.gif", successes=list(r.success))
    with Image.open(gif) as im:
        assert im.n_frames == max(len(p) for p in r.paths) >= 2
    assert not list(tmp_path.glob(".*tmp*"))  # written atomically, nothing left beside it
