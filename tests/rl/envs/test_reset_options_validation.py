"""The env's reset(options=...) and step limit are checked where they are given: a fractional, NaN, malformed,
missing or unknown start/target, and a non-positive max_steps, are typed ValueErrors naming the key and the accepted
form, and a refused reset leaves the episode as it was."""

import math

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import DtradarError, InvalidCoordinatesError, InvalidSettingError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryGymEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.twins import load_dataset


@pytest.fixture(scope="module")
def small():
    return load_dataset("synthetic-12x8/blueprint")


@pytest.fixture()
def env(small):
    return DtradarNavEnv(small)


def free_pair(env):
    free = np.flatnonzero(env.mdp.free)
    s, t = (int(c) for c in env.mdp.sample_pairs(1, np.random.default_rng(0))[0])
    assert s in free and t in free
    return tuple(int(v) for v in env.mdp.xy(s)), tuple(int(v) for v in env.mdp.xy(t))


@pytest.mark.parametrize(
    "bad, key",
    [
        ({"target": (1.5, 2)}, "target"),
        ({"target": (float("nan"), 2)}, "target"),
        ({"start": (1, math.inf)}, "start"),
        ({"target": (1, 2, 3)}, "target"),
        ({"target": (1,)}, "target"),
        ({"target": "1,2"}, "target"),
        ({"target": 7}, "target"),
        ({"target": None}, "target"),
        ({"target": (True, 2)}, "target"),
        ({"target": (99, 2)}, "target"),
        ({"start": (-1, 0)}, "start"),
    ],
)
def test_a_malformed_start_or_target_is_a_typed_error_naming_the_key_and_the_form(env, bad, key):
    start, target = free_pair(env)
    options = {"start": start, "target": target, **bad}
    with pytest.raises(InvalidCoordinatesError, match=f"'{key}'") as err:
        env.reset(options=options)
    assert isinstance(err.value, ValueError) and isinstance(err.value, DtradarError)
    assert "(ix, iy)" in str(err.value)


def test_a_missing_unknown_or_non_dict_option_is_named(env):
    start, target = free_pair(env)
    with pytest.raises(InvalidCoordinatesError, match="'target' without 'start'|'start'"):
        env.reset(options={"target": target})
    with pytest.raises(InvalidCoordinatesError, match="unknown reset option.*'targt'"):
        env.reset(options={"start": start, "targt": target})
    with pytest.raises(InvalidCoordinatesError, match="must be a dict"):
        env.reset(options=[("start", start), ("target", target)])
    with pytest.raises(InvalidCoordinatesError, match="same cell"):
        env.reset(options={"start": start, "target": start})


def test_a_blocked_cell_names_its_key(env):
    iy, ix = (int(v) for v in np.argwhere(env.mdp.blocked)[0])
    _, target = free_pair(env)
    with pytest.raises(InvalidCoordinatesError, match=rf"'start': cell \({ix}, {iy}\) is blocked"):
        env.reset(options={"start": (ix, iy), "target": target})


def test_good_options_in_every_integer_form_are_taken_and_a_refused_reset_changes_nothing(env):
    start, target = free_pair(env)
    for form in (lambda c: c, list, np.array, lambda c: tuple(np.int32(v) for v in c), lambda c: tuple(map(float, c))):
        _, info = env.reset(options={"start": form(start), "target": form(target)})
        assert info["cell"] == start and info["target"] == target
    with pytest.raises(InvalidCoordinatesError):
        env.reset(seed=5, options={"start": start, "target": (0.5, 0)})
    assert (env._info(False)["cell"], env._info(False)["target"]) == (start, target)
    _, info = env.reset(options={})  # no options: a random pair, as before
    assert info["cell"] != info["target"]


def test_the_memory_env_checks_the_same_options(small):
    env = MemoryGymEnv(small, obs="neighbors", memory_radius=1)
    start, _ = free_pair(env)
    with pytest.raises(InvalidCoordinatesError, match="'target'"):
        env.reset(options={"start": start, "target": (2.5, 1)})


@pytest.mark.parametrize("max_steps", [-1, -100, 2.5, float("nan"), "10", True])
def test_a_step_limit_that_is_no_positive_whole_number_is_refused_by_both_envs(small, max_steps):
    with pytest.raises(InvalidSettingError, match="max_steps"):
        DtradarNavEnv(small, max_steps=max_steps)
    with pytest.raises(InvalidSettingError, match="max_steps"):
        BatchedNavEnv.from_dataset(small, 2, max_steps=max_steps)


def test_the_default_and_a_positive_step_limit_are_kept(small):
    assert DtradarNavEnv(small).max_steps == DtradarNavEnv(small, max_steps=0).max_steps == 4 * (12 + 8)
    assert DtradarNavEnv(small, max_steps=7).max_steps == 7
    assert BatchedNavEnv.from_dataset(small, 2, max_steps=9).max_steps == 9


def test_the_batched_env_checks_the_cells_it_is_given(small):
    env = BatchedNavEnv.from_dataset(small, 2)
    (s, t) = (int(c) for c in env.mdp.sample_pairs(1, np.random.default_rng(0))[0])
    blocked = int(np.flatnonzero(env.mdp.blocked.ravel())[0])
    mask = torch.ones(2, dtype=torch.bool)
    for starts, targets, match in [
        ([s, s], [t + 0.5, t], "integer cell indices"),
        ([s], [t], "1 cells for 2 robots"),
        ([s, s], [t, 10_000], "off the 12 x 8 grid or not free"),
        ([s, blocked], [t, t], "off the 12 x 8 grid or not free"),
        ([s, t], [t, t], "its target's cell"),
        ([s, s], None, "starts without targets"),
    ]:
        with pytest.raises(InvalidCoordinatesError, match=match):
            env.reset_where(mask, starts=starts, targets=targets)
    env.reset_where(mask, starts=[s, s], targets=[t, t])
    assert env.cell.tolist() == [s, s] and env.target.tolist() == [t, t]
