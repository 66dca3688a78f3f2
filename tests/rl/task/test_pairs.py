"""The paper's Table VI pairs on our grids: transform, snapping, fixed-pair training and its safety cap."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.grid import Grid
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.scenes import load_scene_spec
from dtradar_rl.cli import main
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.pairs import CAP_FACTOR, TABLE_VI, PairError, largest_region, resolve, to_grid, training_pair
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy


@pytest.mark.parametrize("scene", ["cubicle", "meeting"])
def test_the_table_vi_pair_of_an_indoor_twin_lands_on_free_connected_cells(scene):
    spec = load_scene_spec(scene, "blueprint")  # the scene file's grid and obstacles: no ray tracer, no dataset
    mdp = GridMDP.from_blocked(occupancy(spec), name=scene)
    pair = resolve(mdp, spec.grid, scene)
    region = largest_region(mdp)
    s, t = pair.cells(mdp.nx)
    assert pair.source == "table6"
    assert not mdp.blocked[pair.start[1], pair.start[0]] and not mdp.blocked[pair.target[1], pair.target[0]]
    assert region[s] and region[t] and mdp.connected(s, t)
    assert pair.shortest > 0 and pair.cap >= CAP_FACTOR * pair.shortest


def test_indoor_pairs_read_as_cell_offsets_from_the_grid_centre():
    grid = Grid(x0_m=0.25, y0_m=0.25, cell_m=0.5, nx=42, ny=18)
    assert to_grid(TABLE_VI["cubicle"], grid) == ((13, 0), (38, 17))  # [-8, -9] -> [17, 8] around (21, 9)
    meeting = Grid(x0_m=0.125, y0_m=0.125, cell_m=0.25, nx=38, ny=40)
    assert to_grid(TABLE_VI["meeting"], meeting) == ((0, 0), (36, 37))  # [-20, -22] is clamped onto the grid


def test_city_pairs_read_as_metres_in_the_scene_frame_clamped_onto_the_quadrant():
    q3 = Grid(x0_m=2.0, y0_m=2.0, cell_m=4.0, nx=54, ny=67)  # Dallas Q3: the north-east quadrant
    assert to_grid(TABLE_VI["dallas-q3"], q3) == ((50, 0), (0, 40))
    q1 = Grid(x0_m=-214.0, y0_m=-266.0, cell_m=4.0, nx=54, ny=67)
    assert to_grid(TABLE_VI["dallas-q1"], q1) == ((0, 0), (10, 66))  # [-275, -328] lies outside: the corner


def test_a_blocked_end_snaps_to_the_nearest_cell_of_the_largest_free_region():
    blocked = np.zeros((5, 6), bool)
    blocked[:, 2] = True  # a wall: the left region (2 columns) is smaller than the right one (3)
    blocked[0, 5] = True
    mdp = GridMDP.from_blocked(blocked)
    pair = resolve(mdp, Grid(x0_m=0, y0_m=0, cell_m=1, nx=6, ny=5), "no-such-scene", (3, 0), (5, 4))
    assert pair.source == "given" and pair.shortest == 6
    with pytest.raises(PairError, match="blocked"):
        resolve(mdp, Grid(x0_m=0, y0_m=0, cell_m=1, nx=6, ny=5), "x", (2, 0), (5, 4))
    with pytest.raises(PairError, match="not connected"):
        resolve(mdp, Grid(x0_m=0, y0_m=0, cell_m=1, nx=6, ny=5), "x", (0, 0), (5, 4))


def test_the_paper_preset_trains_on_one_pair_and_its_episodes_are_not_cut_before_the_safety_cap(tmp_path):
    cfg = config_for(
        "paper",
        scene="synthetic-12x8",
        episodes=3,
        hidden=(16,),
        learning_starts=10**9,
        eps_start=0.0,
        eps_end=0.0,
        threads=1,
        verbose=False,
        checkpoint_every=0,
        out=str(tmp_path),
    )
    ds = load_dataset("synthetic-12x8/blueprint")
    pair = training_pair(cfg, ds)
    mdp = GridMDP.from_dataset(ds)
    assert pair.cap >= CAP_FACTOR * pair.shortest > mdp.max_steps  # longer than the goal-conditioned limit

    # A robot pressing into the grid's edge from the pair's corner start is truncated at the cap, not before.
    env = BatchedNavEnv.from_dataset(ds, 1, obs="paper", reward="paper", max_steps=pair.cap)
    s, t = pair.cells(mdp.nx)
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[s], targets=[t])
    against_wall = int(np.flatnonzero(mdp.collides[s])[0])
    for k in range(1, pair.cap + 1):
        _, _, terminated, truncated, _ = env.step(torch.tensor([against_wall]))
        assert bool(truncated[0]) == (k == pair.cap) and not bool(terminated[0])

    # Training: every episode starts at the pair and ends at its target or at exactly the cap.
    result = train(cfg, dataset=ds)
    rows = [line.split(",") for line in (result.out_dir / "curves.csv").read_text().splitlines()[1:]]
    assert len(rows) == 3
    for _, _, _, steps, _, success in rows:
        assert success == "True" or int(steps) == pair.cap
    assert tuple(load_policy(result.checkpoint).meta["stats"]["pair"]["start"]) == pair.start

    # make eval runs a fixed-pair agent on its own pair, on each twin, instead of on random pairs.
    assert (
        main(
            [
                "eval",
                "--scene",
                "synthetic-12x8",
                "--checkpoint",
                str(result.checkpoint),
                "--out",
                str(tmp_path / "eval"),
                "--plot-paths",
                "1",
            ]
        )
        == 0
    )
    rows = json.loads((tmp_path / "eval" / "results.json").read_text())["results"]
    assert [r["pairs"] for r in rows] == [1, 1] and tuple(rows[0]["pair"]["start"]) == pair.start


def test_a_fixed_pair_needs_both_ends_and_no_obstacle_augmentation():
    with pytest.raises(ConfigError, match="--start and --target"):
        config_for("paper", scene="synthetic", start=(1, 1))
    with pytest.raises(ConfigError, match="augmentation"):
        config_for("robust", scene="synthetic", pair="paper")
