"""The expert of fine-tuning: the twin's breadth-first shortest moves, and DQfD's large-margin loss on them."""

import pytest
import torch

from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryNavEnv
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import expert_margin_loss, train
from dtradar_rl.train.saved_runs import load_policy


@pytest.fixture(scope="module")
def synth():
    return load_dataset("synthetic/dynamic")


def _walk_shortest(env: BatchedNavEnv) -> None:
    """Every robot follows its first shortest move; each must reach its target in exactly its BFS distance."""
    start_dist = env._potential(env.cell).long()
    assert bool((start_dist > 0).all())
    done = torch.zeros(env.num_envs, dtype=torch.bool)
    for step in range(1, int(start_dist.max()) + 1):
        moves = env.shortest_moves()
        assert bool(moves[~done].any(1).all()), "a robot short of its target has no shortest move"
        _, _, terminated, _, info = env.step(moves.float().argmax(1))
        assert not bool(info["collision"][~done].any())
        assert bool((terminated == (start_dist == step))[~done].all())
        done |= terminated


@pytest.mark.parametrize("aug", [0, 6])
def test_following_the_shortest_moves_reaches_every_target_in_its_breadth_first_distance(synth, aug):
    env = BatchedNavEnv.from_dataset(synth, 128, obs="neighbors", reward="geodesic", seed=3, aug_obstacles=aug)
    env.reset()
    _walk_shortest(env)


def test_memory_envs_give_the_same_shortest_moves(synth):
    env = MemoryNavEnv.from_dataset(synth, 64, reward="geodesic", seed=4, memory_radius=2, aug_obstacles=4)
    env.reset()
    _walk_shortest(env)


def test_shortest_moves_need_the_geodesic_distance_tables(synth):
    env = BatchedNavEnv.from_dataset(synth, 4, obs="neighbors", reward="euclidean", seed=0)
    env.reset()
    with pytest.raises(InvalidCoordinatesError, match="geodesic"):
        env.shortest_moves()


def test_the_margin_loss_is_zero_once_expert_moves_lead_by_the_margin_and_ignores_states_without_one():
    q = torch.tensor([[2.0, 0.5, 0.9, 0.0], [0.0, 1.0, 0.0, 0.0], [5.0, 0.0, 0.0, 0.0]])
    expert = torch.tensor([[True, False, False, False], [True, False, True, False], [False] * 4])
    # row 0: expert leads by 1.1 >= 1 -> 0; row 1: best expert 0.0, best other 1.0 + 1 -> 2; row 2: no expert
    assert expert_margin_loss(q, expert, 1.0).item() == pytest.approx(1.0)
    assert expert_margin_loss(q[:1], expert[:1], 1.0).item() == 0.0
    assert expert_margin_loss(q[2:], expert[2:], 1.0).item() == 0.0


def test_the_wait_action_is_never_an_expert_move_and_trails_the_expert_by_the_margin():
    # a fifth (wait) value beside four moves: the expert's four columns are padded with "not expert"
    q = torch.tensor([[2.0, 0.5, 0.9, 0.0, 1.5], [2.0, 0.5, 0.9, 0.0, 0.5]])
    expert = torch.tensor([[True, False, False, False], [True, False, False, False]])
    # row 0: wait 1.5 + 1 = 2.5 over the expert's 2.0 -> 0.5; row 1: the expert leads everything by >= 1 -> 0
    assert expert_margin_loss(q, expert, 1.0).item() == pytest.approx(0.25)


def test_training_with_the_wait_action_and_the_expert_loss_runs(tmp_path):
    cfg = config_for(
        "tuned",
        scene="synthetic-moving-12x8",
        wait_action=True,
        expert_weight=1.0,
        total_env_steps=2_000,
        num_envs=16,
        learning_starts=128,
        env_steps_per_update=8,
        verbose=False,
        threads=1,
        checkpoint_every=0,
        out=str(tmp_path / "wait-expert"),
    )
    res = train(cfg)
    assert load_policy(res.checkpoint).q.net[-1].out_features == 5


def test_the_expert_loss_needs_the_geodesic_reward_and_a_positive_margin():
    with pytest.raises(ConfigError, match="geodesic"):
        config_for("tuned", expert_weight=1.0, reward="scaled").validate()
    with pytest.raises(ConfigError, match="expert"):
        config_for("tuned", expert_weight=1.0, expert_margin=0.0).validate()


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_training_with_the_expert_loss_learns_the_shortest_moves(tmp_path):
    common = dict(
        scene="synthetic-12x8",
        total_env_steps=6_000,
        num_envs=32,
        learning_starts=256,
        env_steps_per_update=8,
        verbose=False,
        threads=1,
        checkpoint_every=0,
        eps_decay_fraction=0.2,
    )
    res = train(config_for("tuned", **common, expert_weight=1.0, out=str(tmp_path / "expert")))
    m, _ = evaluate(
        load_policy(res.checkpoint), load_dataset("synthetic-12x8/blueprint"), pairs=100, seed=0, latency=False
    )
    assert m.success_rate >= 0.9 and m.spl >= 0.85


@pytest.mark.parametrize("wait", [True, False])
def test_on_a_moving_twin_the_shortest_moves_reach_the_target_in_time_and_meet_no_mover(wait):
    ds = load_dataset("synthetic-moving-12x8/blueprint")
    env = BatchedNavEnv.from_dataset(ds, 64, obs="neighbors", reward="geodesic", seed=5, wait_action=wait)
    env.reset()
    moves = env.shortest_moves()
    assert moves.shape == (64, 5 if wait else 4)
    cells = env.mdp.num_cells
    dist = env._st_dist[env.tpool, env.t * cells + env.cell].long()
    # with free waiting every robot whose target the movers leave reachable has a shortest action; without the wait
    # action a robot that must wait in the open has none, so it is left out of the walk
    walking = (dist > 0) & moves.any(1)
    assert bool(walking.any()) and (not wait or bool(walking[dist > 0].all()))
    done = ~walking
    for step in range(1, int(dist[walking].max()) + 1):
        moves = env.shortest_moves()
        stuck = ~done & ~moves.any(1)
        done |= stuck  # only without the wait action: a wait in the open was the shortest way
        assert wait is False or not bool(stuck.any())
        _, _, terminated, _, info = env.step(moves.float().argmax(1))
        assert not bool((info["collision"] | info["mover_hit"])[~done].any()), "a shortest move met a mover"
        assert bool((terminated == (dist == step))[~done].all())
        done |= terminated
    assert bool(done.all())
