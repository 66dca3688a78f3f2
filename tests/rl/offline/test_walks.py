"""The OGBench-style families walk as named: navigate goes on from each goal it reaches, stitch hops to near goals,
explore keeps its last move; each logs like any family, its walk in the version."""

import numpy as np
import pytest

from dtradar_rl.offline.behaviours import BehaviourSpec
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.walks import EXPLORE_KEEP, STITCH_HOP
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset

SCENE = "synthetic-12x8"
SETTINGS = dict(scene=SCENE, steps=6000, num_envs=16, seed=0, minari=False, verbose=False)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp_path_factory.mktemp("walks") / "root"))
        yield {b: log_dataset(LogConfig(behaviour=b, **SETTINGS)) for b in ("navigate", "stitch", "explore")}


def _boundaries(a):
    """Rows where a robot's episode ended and its next one starts (same robot)."""
    ends = a["terminated"] | a["truncated"]
    same = a["robot"][1:] == a["robot"][:-1]
    return np.flatnonzero(ends[:-1] & same)


def test_navigate_goes_on_from_every_goal_it_reaches(logs):
    a = logs["navigate"].arrays()
    i = _boundaries(a)
    reached = a["terminated"][i]
    assert reached.sum() > 100
    np.testing.assert_array_equal(a["cell"][i + 1][reached], a["target"][i][reached])  # it starts where it stopped
    assert (a["target"][i + 1] != a["cell"][i + 1]).all()
    assert logs["navigate"].meta["family"] == "navigate"


def test_stitch_hops_to_goals_a_few_moves_away(logs):
    a = logs["stitch"].arrays()
    mdp = GridMDP.from_dataset(load_dataset(f"{SCENE}/blueprint"))
    firsts = a["step"] == 0
    (x0, y0), (x1, y1) = mdp.xy(a["cell"][firsts]), mdp.xy(a["target"][firsts])
    hop = np.abs(x0 - x1) + np.abs(y0 - y1)
    assert (hop[1:] <= STITCH_HOP).mean() > 0.95 and (hop >= 1).all()  # (the very first episodes are the env's own)


def test_explore_keeps_its_last_move_unless_it_bumped(logs):
    a = logs["explore"].arrays()
    same_robot = a["robot"][1:] == a["robot"][:-1]
    moved = a["cell"][1:] != a["cell"][:-1]
    keep = (a["action"][1:] == a["action"][:-1])[same_robot & moved]
    assert abs(keep.mean() - (EXPLORE_KEEP + (1 - EXPLORE_KEEP) / 4)) < 0.05


def test_a_walks_parameters_enter_its_version():
    d = BehaviourSpec(kind="stitch").to_dict()
    assert d["walk"] == {"shortest_prob": 0.9, "hop": STITCH_HOP}
    assert BehaviourSpec(kind="explore").to_dict()["walk"] == {"explore_keep": EXPLORE_KEEP}
    assert "OGBench" in BehaviourSpec(kind="navigate").describe()
