"""The planner among movers: it gives way to a mover it senses next to it, predicting where the mover goes next."""

import numpy as np
import pytest
import torch

from dtradar_data.pipeline.synthetic import Mover, synthetic_moving_dataset
from dtradar_rl.agents.planner import FingerprintPlanner, predicted_risk
from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for

# A corridor (y = 1) walled in above and below but for a niche on (3, 0); a walker goes back and forth over x = 1..3
# (at snapshot k: x = 1, 2, 3, 2, 1, ...), so at snapshot 1 it stands on (2, 1) and walks onto (3, 1) next.
#
#   y=2  # # # # # # #
#   y=1  . m m m . . .
#   y=0  # # # . # # #
WALLS = np.ones((3, 7), bool)
WALLS[1] = False
WALLS[0, 3] = False


@pytest.fixture(scope="module")
def corridor():
    return synthetic_moving_dataset(7, 3, movers=[Mover("walker", (1, 1), "x", 3)], blocked=WALLS, name="corridor/x")


def one_step(ds, predict: bool, start, target, t0):
    planner = FingerprintPlanner(ds)
    env = planner.env_for(ds, 1, reward="paper")
    planner.predict = predict
    mdp = env.mdp
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[mdp.cell(*start)], targets=[mdp.cell(*target)], t0=t0)
    action = planner.act(env.observe())
    _, _, _, _, info = env.step(action)
    return int(action), {k: bool(info[k][0]) for k in ("collision", "mover_collision", "mover_hit")}


def test_beside_a_mover_a_step_to_the_side_is_the_safest_move_and_the_plan_weighs_in():
    movers = torch.tensor([[True, False, False, False]])  # a mover on X-
    risk = predicted_risk(movers, torch.tensor([[False, False, False, False]]))[0]
    # straight away is the riskiest (an oncoming mover covers the cell behind the robot too), then into it
    assert risk[1] > risk[0] > risk[2] == risk[3] > 0
    walled = predicted_risk(movers, torch.tensor([[False, True, True, False]]))[0]
    assert walled[3] < walled[2] < walled[0]  # the open side, then a wall bump (it never collides), then the mover
    off = predicted_risk(
        movers, torch.tensor([[False, False, True, False]]), torch.tensor([[False, False, True, True]])
    )
    assert off[0].argmin() == 3 and off[0, 3] > risk[3]  # off the plan costs more, a side step is still the best


def test_next_to_an_oncoming_mover_the_planner_steps_aside_instead_of_pushing_into_it(corridor):
    # the robot on (3, 1) heads for (0, 1); the walker on (2, 1) comes onto (3, 1) at the next snapshot
    old_action, old = one_step(corridor, False, (3, 1), (0, 1), t0=1)
    assert old_action == 0 and old["mover_collision"]  # no way round: it pushed, and they would pass through
    action, new = one_step(corridor, True, (3, 1), (0, 1), t0=1)
    assert action == 2 and not any(new.values())  # into the niche: no collision, and the walker passes by


def test_with_no_mover_in_sight_the_prediction_changes_nothing(corridor):
    for t0 in range(4):
        for start in [(5, 1), (6, 1)]:
            assert one_step(corridor, False, start, (0, 1), t0)[0] == one_step(corridor, True, start, (0, 1), t0)[0]


class PrefersXMinus(QNetwork):
    """A Q-network that always prefers move 0 (X-), then 3, 2, 1."""

    def __init__(self):
        super().__init__(8, (1,))

    def forward(self, x):
        return torch.tensor([4.0, 1.0, 2.0, 3.0]).expand(x.shape[0], 4)


def test_a_shielded_policy_on_a_moving_twin_gives_way_to_a_mover_and_on_a_static_twin_has_no_mover_guard(corridor):
    cfg = config_for(scene="synthetic-12x8")
    p = Policy(PrefersXMinus(), cfg, Normalizer.fit(corridor), "neighbors", {})
    outcomes = {}
    for shield in (False, True):
        env = p.env_for(corridor, 1, reward="paper")
        env.reset_where(
            torch.ones(1, dtype=torch.bool), starts=[env.mdp.cell(3, 1)], targets=[env.mdp.cell(0, 1)], t0=1
        )
        action = p.act(env.observe(), shield=shield)
        outcomes[shield] = int(action), bool(env.step(action)[4]["mover_collision"][0])
    assert outcomes[False] == (0, True)  # into the walker as it comes onto the robot's cell
    assert outcomes[True] == (2, False)  # into the niche, aside: the walker passes by
    assert p.mover_guard is not None
    p.env_for(load_dataset("synthetic-12x8/blueprint"), 1)
    assert p.mover_guard is None  # a static twin's shield is the plain one
