"""Honest observations hold no position and no other cell's radio: proved by construction, not by column names.

Each test rewrites a twin everywhere the robot may not look (every cell's ``x_m, y_m`` but the target's, every other
cell's radio) and checks that the robot's observation does not change by one bit; and that it does change when the
robot's own cell's radio does (so the check can fail)."""

import numpy as np
import pyarrow as pa
import pytest
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.schema import tx_column
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.task.sensing import SENSINGS, honest_dim, honest_names
from dtradar_rl.task.twins import load_dataset

RADIO = ("aoa_az_rad", "aoa_zen_rad", "aod_az_rad", "aod_zen_rad", "tau_s", "a_re", "a_im", "phase_rad")


def rewritten(ds: Dataset, keep: set[int], rng: np.random.Generator) -> Dataset:
    """``ds`` with random radio on every cell not in ``keep`` and random ``x_m, y_m`` on every cell (the target's
    coordinates, which the robot is given, restored after)."""
    table = ds.table
    for k in range(ds.transmitters):
        for c in RADIO:
            name = tx_column(c, k)
            v = table.column(name).to_numpy(zero_copy_only=False).astype(np.float64).copy()
            others = np.setdiff1d(np.arange(len(v)), sorted(keep))
            v[others] = rng.normal(size=others.size)
            i = table.column_names.index(name)
            table = table.set_column(i, name, pa.array(v.astype(np.float32), mask=np.isnan(v)))
    for c in ("x_m", "y_m"):
        v = table.column(c).to_numpy(zero_copy_only=False).astype(np.float64) + rng.normal(size=table.num_rows) * 50
        table = table.set_column(table.column_names.index(c), c, pa.array(v))
    return Dataset(ds.name, table, ds.meta, ds.version, ds.path)


def observe(ds: Dataset, start: int, target: int, actions, sensing="radio", noise="none") -> list[torch.Tensor]:
    env = HonestNavEnv.from_dataset(ds, 1, sensing=sensing, noise=noise, seed=3, reward="paper")
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[start], targets=[target])
    out = [env.observe()]
    for a in actions:
        out.append(env.step(torch.tensor([a]))[0])
    return out


@pytest.mark.parametrize("noise", ["none", "realistic"])
@pytest.mark.parametrize("sensing", ["radio", "rssi", "no-radio"])
def test_an_honest_observation_does_not_change_when_positions_and_other_cells_radio_change(sensing, noise):
    ds = load_dataset("synthetic/blueprint")
    free = np.flatnonzero(~np.asarray(ds.blocked).ravel())
    start, target = int(free[0]), int(free[-1])
    actions = [1, 1, 3, 0, 2, 1]
    before = observe(ds, start, target, actions, sensing, noise)
    # the cells the robot stands on along the way keep their radio; everything else is rewritten
    env = HonestNavEnv.from_dataset(ds, 1, reward="paper")
    env.reset_where(torch.ones(1, dtype=torch.bool), starts=[start], targets=[target])
    visited = {start}
    for a in actions:
        env.step(torch.tensor([a]))
        visited.add(int(env.cell))
    twin = rewritten(ds, visited, np.random.default_rng(0))
    xy = twin.table.column("x_m").to_numpy().copy(), twin.table.column("y_m").to_numpy().copy()
    for c, v in zip(("x_m", "y_m"), xy):  # the target's own coordinates are what the robot is told
        v[target] = ds.table.column(c).to_numpy()[target]
        twin = Dataset(twin.name, twin.table.set_column(twin.table.column_names.index(c), c, pa.array(v)), twin.meta)
    after = observe(twin, start, target, actions, sensing, noise)
    for b, a in zip(before, after):
        assert torch.equal(b, a)


def test_an_honest_observation_changes_with_the_robots_own_cell_radio():
    ds = load_dataset("synthetic/blueprint")
    free = np.flatnonzero(~np.asarray(ds.blocked).ravel())
    start, target = int(free[0]), int(free[-1])
    twin = rewritten(ds, set(), np.random.default_rng(1))  # the start's radio rewritten too
    assert not torch.equal(observe(ds, start, target, [])[0], observe(twin, start, target, [])[0])


def test_two_cells_with_the_same_own_readings_look_the_same_wherever_they_are():
    ds = load_dataset("synthetic/blueprint")
    table = ds.table
    a, b = np.flatnonzero(~np.asarray(ds.blocked).ravel())[[5, 40]]
    for c in RADIO:  # cell b measures exactly what cell a does
        v = table.column(c).to_numpy(zero_copy_only=False).astype(np.float64).copy()
        v[b] = v[a]
        table = table.set_column(table.column_names.index(c), c, pa.array(v.astype(np.float32), mask=np.isnan(v)))
    twin = Dataset(ds.name, table, ds.meta)
    env = HonestNavEnv.from_dataset(twin, 2, reward="paper")
    target = int(np.flatnonzero(~np.asarray(ds.blocked).ravel())[-1])
    env.reset_where(torch.ones(2, dtype=torch.bool), starts=[a, b], targets=[target, target])
    obs = env.observe()
    radio = slice(0, 8)  # one transmitter: its measured quantities and the heard flag
    assert torch.equal(obs[0, radio], obs[1, radio])
    assert torch.equal(obs[0, 8 + 4 :], obs[1, 8 + 4 :])  # odometry and target: nothing tells a from b


def test_the_honest_layout_has_the_width_and_names_it_documents():
    ds = load_dataset("synthetic/blueprint")
    env = HonestNavEnv.from_dataset(ds, 3, reward="paper")
    assert env.reset().shape == (3, honest_dim(1)) == (3, len(honest_names(1)))
    assert "x_m" not in honest_names(1) and "target_x_m" in honest_names(1)


def test_the_privileged_setting_is_refused_by_the_honest_env():
    ds = load_dataset("synthetic/blueprint")
    with pytest.raises(ValueError, match="privileged"):
        HonestNavEnv.from_dataset(ds, 1, sensing=SENSINGS["privileged"])


def test_the_honest_gymnasium_env_plays_an_episode_to_its_target_without_telling_the_position():
    import gymnasium as gym

    from dtradar_rl.envs.registration import register_dataset_envs

    register_dataset_envs()
    env = gym.make("dtradar/synthetic-blueprint-honest-v0", noise="none")
    obs, info = env.reset(seed=1, options={"start": (1, 1), "target": (3, 1)})
    assert obs.shape == env.observation_space.shape and "x_m" not in info["names"]
    assert obs[info["names"].index("switched_on")] == 1.0
    obs, reward, terminated, truncated, step_info = env.step(1)  # X+
    assert obs[info["names"].index("moved")] == 1.0 and obs[info["names"].index("last[X+]")] == 1.0
    obs, reward, terminated, truncated, step_info = env.step(1)
    assert terminated and step_info["is_success"]


def test_with_no_radio_the_receiver_is_off_not_even_whether_a_transmitter_is_heard(two_tx):
    env = HonestNavEnv.from_dataset(two_tx, 4, sensing="no-radio", noise="realistic", reward="paper")
    obs = env.reset()
    assert torch.count_nonzero(obs[:, : 2 * 8]) == 0  # both transmitters' measured quantities and heard flags
    rssi = HonestNavEnv.from_dataset(two_tx, 4, sensing="rssi", reward="paper").reset()
    gain, heard = [7 - 2, 7], [8 + 7 - 2, 8 + 7]  # each transmitter's gain_db and heard columns
    assert torch.count_nonzero(rssi[:, gain + heard]) > 0
    assert torch.count_nonzero(rssi[:, [0, 1, 2, 3, 4, 6, 8, 9, 10, 11, 12, 14]]) == 0  # nothing but the gain
