"""How far the paper's protocol stands from its pair: exact hitting times and the optimum of the paper's MDP."""

import numpy as np
import pytest

from dtradar_rl.experiments.paper_reach import analyse, hitting_times, transition_matrix
from dtradar_rl.tabular.solver import TabularMDP
from dtradar_rl.task.grid_mdp import GridMDP


def tab_of(blocked) -> TabularMDP:
    return TabularMDP.from_mdp(GridMDP.from_blocked(np.asarray(blocked, bool)))


def test_a_uniform_walk_hits_the_end_of_a_corridor_with_the_probabilities_counted_by_hand():
    # cells 0-1-2 in a row; each step: X+ moves on, X- moves back (bumps at 0), Y-/Y+ bump: from 0, 1/4 to move on
    tab = tab_of([[False, False, False]])
    p = transition_matrix(tab, np.full((3, 4), 0.25), target=2)
    h = hitting_times(p, start=0, target=2, caps=(1, 2, 3))
    # by step 2 only 0 -> 1 -> 2 (1/16); at step 3: stay, 1, 2 (3/64) or 1, stay, 2 (2/64)
    assert h["within"] == pytest.approx({1: 0.0, 2: 1 / 16, 3: 9 / 64})
    assert p.sum(1).A1 == pytest.approx(np.ones(3))  # every row a distribution, the target's absorbing


def test_the_paper_optimum_walks_straight_to_a_target_in_the_open():
    tab = tab_of(np.zeros((8, 8), bool))
    r = analyse(tab, start_cell=0, target_cell=63, cap=140)
    assert r["shortest"] == 14
    assert r["optimum"] == {"reached": True, "steps": 14, "settles": None, "closest": 0}
    assert r["chains"]["eps_optimal"]["within"]["140"] > 0.999  # ε = 0.1 on the optimum: found in every episode
    assert r["chains"]["uniform"]["within"]["140"] < r["chains"]["eps_optimal"]["within"]["140"]


def test_the_paper_optimum_settles_below_a_wall_when_the_way_round_is_long():
    # a wall across the grid with its only gap at the far right: the step cost -(dx² + dy²) at γ = 0.9 makes waiting
    # below the wall, 6 cells from the target in a straight line, worth more than the detour and the +5000
    blocked = np.zeros((12, 40), bool)
    blocked[5, :39] = True
    tab = tab_of(blocked)
    start, target = 1 * 40 + 20, 10 * 40 + 20
    r = analyse(tab, start_cell=start, target_cell=target, cap=400)
    o = r["optimum"]
    assert not o["reached"] and o["steps"] is None
    assert o["settles_at"] >= 6 and o["closest"] <= o["settles_at"]
    assert all(blocked.ravel()[c] == 0 for c in o["settles"])
    # the ε-greedy optimum rarely escapes it; an untrained walk finds the gap more often
    e, u = r["chains"]["eps_optimal"]["within"]["400"], r["chains"]["uniform"]["within"]["400"]
    assert e < u
