"""Tables with senses: a table followed by a robot that forbids what it senses or bumps into and re-plans; where
nothing changed it is the table itself, where objects appeared it goes round them; the tracker carries the belief
along the robot's own moves. Tiny synthetic twins."""

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.tabular.batch import BatchConfig, empirical_model, learn
from dtradar_rl.tabular.evaluation import follow, path_metrics, policy_values
from dtradar_rl.tabular.fingerprints import Tracker, localisation
from dtradar_rl.tabular.sensing import follow_sensing, neighbour_cells, radio_flags
from dtradar_rl.tabular.solver import TabularMDP, bellman_sweeps
from dtradar_rl.task.twins import load_dataset

SCENE = "synthetic-10x6"
CFG = LogConfig(scene=SCENE, behaviour="random", steps=6000, num_envs=16, seed=0, minari=False, verbose=False)
EXACT = BatchConfig(lcb_beta=0.0)


@pytest.fixture()
def setting(root):
    bp, dyn = load_dataset(f"{SCENE}/blueprint"), load_dataset(f"{SCENE}/dynamic")
    tab = TabularMDP.from_dataset(bp)
    return bp, dyn, tab, empirical_model(log_dataset(CFG), tab)


def _run(name, model, bp, twin, pairs, tracker=True):
    targets = np.unique(pairs[:, 1])
    rows = np.searchsorted(targets, pairs[:, 1])
    table = learn(name, model, targets, EXACT)
    tab = TabularMDP.from_dataset(twin)
    paths = follow_sensing(
        name,
        model,
        table,
        rows,
        tab,
        localisation(bp, twin),
        radio_flags(twin),
        radio_flags(bp),
        pairs[:, 0],
        pairs[:, 1],
        cfg=EXACT,
        tracker=Tracker(bp, twin, 0) if tracker else None,
    )
    return table, rows, tab, paths


def test_where_nothing_changed_a_sensing_table_is_the_table_itself(setting):
    bp, _, tab, model = setting
    pairs = sample_eval_pairs(bp, 200, 0)
    for name in ("ce", "lcb"):
        table, rows, _, paths = _run(name, model, bp, bp, pairs)
        plain = follow(tab, table, rows, pairs[:, 0], pairs[:, 1], tab.mdp.max_steps)
        for k in ("success", "steps", "travelled", "collisions"):
            np.testing.assert_array_equal(paths[k], plain[k])
        assert paths["replans"].sum() == 0
        targets = np.unique(pairs[:, 1])
        v = policy_values(tab, table, targets, model.reward, EXACT.gamma)[rows, tab.states(pairs[:, 0])]
        np.testing.assert_allclose(paths["returns"], v, rtol=1e-9, atol=1e-9)  # the discounted return is exact


def test_a_sensing_table_goes_round_the_objects_that_stop_the_table(setting):
    bp, dyn, _, model = setting
    tab_dyn = TabularMDP.from_dataset(dyn)
    pairs = sample_eval_pairs(dyn, 200, 0)
    targets = np.unique(pairs[:, 1])
    for name in ("ce", "lcb"):
        table, rows, _, paths = _run(name, model, bp, dyn, pairs)
        seen = table[:, TabularMDP.from_dataset(bp).state_of[localisation(bp, dyn)[tab_dyn.cells]]]
        plain = path_metrics(follow(tab_dyn, seen, rows, pairs[:, 0], pairs[:, 1], tab_dyn.mdp.max_steps))
        got = path_metrics(paths)
        assert plain["success_rate"] < 1.0  # the objects stop the table somewhere
        assert got["success_rate"] == 1.0 and got["collisions"] < plain["collisions"]
        assert paths["replans"].sum() > 0
    assert targets.size > 1


def test_the_tracker_follows_the_true_cell_where_the_first_fingerprint_is_right(setting):
    bp, dyn, *_ = setting
    tracker = Tracker(bp, dyn, 0)
    tab = TabularMDP.from_dataset(dyn)
    rng = np.random.default_rng(0)
    cells = tab.cells[tracker.start(tab.cells) == tab.cells]  # where the fingerprint localises right
    s = tab.state_of[cells]
    belief = tracker.start(cells)
    for _ in range(30):
        a = rng.integers(0, 4, s.size)
        nxt = tab.next[s, a]
        belief = tracker.step(belief, a, nxt != s, tab.cells[nxt])
        s = nxt
        np.testing.assert_array_equal(belief, tab.cells[s])


def test_neighbour_cells_are_the_moves_on_the_grid_and_minus_one_off_it(setting):
    bp, *_ = setting
    tab = TabularMDP.from_dataset(bp)
    nb = neighbour_cells(tab.mdp)
    free = tab.cells
    moved = ~tab.collides
    np.testing.assert_array_equal(nb[free][moved], tab.mdp.next_cell[free][moved])
    assert (nb[0] == [-1, 1, -1, tab.mdp.nx]).all()  # the corner cell (0, 0)


def test_a_forbidden_move_is_never_taken_and_bad_forbidden_masks_are_refused(setting):
    _, _, tab, model = setting
    targets = tab.cells[:3]
    forbidden = np.zeros((3, tab.n, 4), bool)
    forbidden[:, :, 1] = True  # never X+
    for name in ("ce", "lcb"):
        a = learn(name, model, targets, EXACT, forbidden=forbidden)
        assert (a != 1).all()
    with pytest.raises(InvalidSettingError, match="SPIBB"):
        learn("spibb", model, targets, EXACT, forbidden=forbidden)
    with pytest.raises(InvalidSettingError, match="forbidden must be"):
        learn("ce", model, targets, EXACT, forbidden=forbidden[:2])


def test_a_state_whose_moves_are_all_forbidden_is_worth_the_floor():
    r = np.full((1, 2, 4), -1.0)
    reached = np.zeros((1, 2, 4), bool)
    nxt = np.array([[1, 1, 1, 1], [0, 0, 0, 0]])
    forbidden = np.zeros((1, 2, 4), bool)
    forbidden[0, 0] = True
    v, _, _ = bellman_sweeps(r, reached, nxt, 0.9, forbidden=forbidden, floor=-10.0)
    assert v[0, 0] == -10.0 and np.isclose(v[0, 1], -1.0 + 0.9 * -10.0)
