"""A policy with the wait action under the shield: the plain shield never refuses a wait, the mover guard rates a
wait as a wall bump off the plan (a step aside beats it beside an oncoming mover), and a loop escape moves."""

import numpy as np
import pytest
import torch

from dtradar_data.pipeline.synthetic import Mover, synthetic_moving_dataset
from dtradar_rl.agents.planner import RISK_OFF_PLAN, RISK_WALL, MoverGuard
from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.task.grid_mdp import WAIT
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for

# The corridor of tests/rl/agents/test_planner_movers.py: a walker on x = 1..3 of y = 1, a niche on (3, 0).
WALLS = np.ones((3, 7), bool)
WALLS[1] = False
WALLS[0, 3] = False


@pytest.fixture(scope="module")
def corridor():
    return synthetic_moving_dataset(7, 3, movers=[Mover("walker", (1, 1), "x", 3)], blocked=WALLS, name="corridor/x")


class PrefersWaiting(QNetwork):
    """A Q-network of five actions that always prefers the wait, then X-, Y+, Y-, X+."""

    def __init__(self):
        super().__init__(8, (1,), n_actions=5)

    def forward(self, x):
        return torch.tensor([4.0, 1.0, 2.0, 3.0, 5.0]).expand(x.shape[0], 5)


def _policy(ds):
    return Policy(
        PrefersWaiting(), config_for(scene="synthetic-12x8", wait_action=True), Normalizer.fit(ds), "neighbors", {}
    )


def test_the_shield_lets_a_robot_wait_where_no_mover_is_near():
    ds = load_dataset("synthetic-12x8/blueprint")
    p = _policy(ds)
    env = p.env_for(ds, 4)
    env.reset()
    assert env.num_actions == 5
    assert (p.act(env.observe(), shield=True) == WAIT).all()


def test_beside_an_oncoming_mover_the_guard_steps_aside_rather_than_wait(corridor):
    p = _policy(corridor)
    env = p.env_for(corridor, 1, reward="paper")
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[env.mdp.cell(3, 1)], targets=[env.mdp.cell(0, 1)], t0=1)
    obs = env.observe()
    assert int(p.act(obs)) == WAIT
    action = p.act(obs, shield=True)
    assert int(action) == 2  # into the niche: the walker passes by
    assert not bool(env.step(action)[4]["mover_hit"][0])


def test_the_guard_rates_a_wait_as_a_wall_bump_off_the_plan(corridor):
    guard = MoverGuard(corridor, Normalizer.fit(corridor))
    assert RISK_WALL + RISK_OFF_PLAN > RISK_WALL  # a wait never beats a bump it could have made on the plan
    p = _policy(corridor)
    env = p.env_for(corridor, 1, reward="paper")
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[env.mdp.cell(3, 1)], targets=[env.mdp.cell(0, 1)], t0=1)
    obs = env.observe()
    only_wait = torch.tensor([[-9.0, -9.0, -9.0, -9.0, 1.0]])
    assert int(guard.give_way(obs, only_wait, torch.tensor([WAIT]))) != WAIT


def test_a_loop_escape_takes_a_move_never_the_wait():
    p = _policy(load_dataset("synthetic-12x8/blueprint"))
    allowed = torch.ones((500, 5), dtype=torch.bool)
    moves = p._escape_moves(torch.zeros((500, 8)), allowed)
    assert int(moves.max()) < WAIT and len(set(moves.tolist())) == 4
