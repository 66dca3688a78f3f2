"""What a process keeps of a log between runs (its relabeller, its memory windows, its d3rlpy dataset) is served only
for the transitions it was built from: a log put back under the same folder and version with other transitions (a
version hashes the logging inputs, not the rows) gets its own, built again with one line saying so; the same rows
loaded again are served the kept one, silently. A relabelled sampler refuses parts built from different logs."""

import dataclasses

import numpy as np
import pytest

from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.store.logged import load_logged
from dtradar_rl.offline import memory_senses as ms
from dtradar_rl.offline import relabeller as rlb
from dtradar_rl.offline import trainer
from dtradar_rl.offline.formats import to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.memory_senses import MemorySenses, memory_senses
from dtradar_rl.offline.relabel import RelabelConfig
from dtradar_rl.offline.relabelled_sampler import relabelled_sampler
from dtradar_rl.offline.relabeller import relabeller
from dtradar_rl.offline.trainer import mdp_dataset
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"
LOG = dict(scene=SMALL, num_envs=16, max_steps=20, minari=False, verbose=False, behaviour="noisy-shortest")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """The small twin, a log of it, and another log of it (another seed, as many steps) put in the first one's
    place: the same folder, name and version, other rows."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp_path_factory.mktemp("root")))
        twin = load_dataset(f"{SMALL}/blueprint")
        first = log_dataset(LogConfig(**LOG, seed=3, steps=1_000), twin)
        other = log_dataset(LogConfig(**LOG, seed=4, steps=1_000), twin)
        assert len(first) == len(other) and not np.array_equal(first.arrays()["cell"], other.arrays()["cell"])
        again = dataclasses.replace(other, name=first.name, version=first.version, path=first.path, tag=first.tag)
        yield twin, first, other, again, load_logged(first.name, first.version)


@pytest.fixture(autouse=True)
def empty_caches():
    for cache in (rlb._CACHE, ms._CACHE, trainer._MDP_CACHE):
        cache.clear()
    yield


def test_a_kept_relabeller_is_built_again_for_other_transitions_and_says_so(logs, capsys):
    twin, first, other, again, reloaded = logs
    kept = relabeller(first, twin)
    assert relabeller(reloaded, twin) is kept, "the same rows loaded again: the kept one"
    assert "built again" not in capsys.readouterr().err
    rebuilt = relabeller(again, twin)
    err = capsys.readouterr().err
    assert rebuilt is not kept
    np.testing.assert_array_equal(rebuilt.cell, other.arrays()["cell"])
    assert f"relabeller kept in this process for {first.name}@{first.version}" in err, err
    assert "building it again" in err


def test_kept_memory_windows_are_built_again_for_other_transitions_and_say_so(logs, capsys):
    twin, first, other, again, reloaded = logs
    mdp = GridMDP.from_dataset(twin)
    kept = memory_senses(first, mdp)
    assert memory_senses(reloaded, mdp) is kept
    rebuilt = memory_senses(again, mdp)
    assert "memory window kept in this process" in capsys.readouterr().err
    s = ms.MEMORY_SETTINGS
    own = MemorySenses(other, mdp, radius=s["memory_radius"], bumps=s["memory_bumps"], visits=s["memory_visits"])
    np.testing.assert_array_equal(rebuilt.window, own.window)


@pytest.mark.parametrize("with_senses", [False, True], ids=["plain", "memory"])
def test_a_kept_d3rlpy_dataset_is_built_again_for_other_transitions_and_says_so(logs, capsys, with_senses):
    twin, first, other, again, reloaded = logs
    mdp = GridMDP.from_dataset(twin)
    senses = (lambda log: memory_senses(log, mdp)) if with_senses else (lambda log: None)
    kept = mdp_dataset(first, senses(first))
    assert mdp_dataset(reloaded, senses(reloaded)) is kept
    rebuilt = mdp_dataset(again, senses(again))
    assert "d3rlpy dataset kept in this process" in capsys.readouterr().err
    actions = lambda data: np.concatenate([ep.actions[:, 0] for ep in data.episodes])  # noqa: E731
    np.testing.assert_array_equal(actions(rebuilt), actions(to_mdp_dataset(other)))


def test_a_relabelled_sampler_refuses_parts_of_different_logs(logs):
    twin, first, other, _, _ = logs
    mix = RelabelConfig(own=0.5, future=0.5, seed=1)
    with pytest.raises(SchemaMismatchError, match="would mix different logs"):
        relabelled_sampler(mdp_dataset(first), relabeller(other, twin), mix)
    mdp = GridMDP.from_dataset(twin)
    with pytest.raises(SchemaMismatchError, match="the memory windows was built from"):
        relabelled_sampler(mdp_dataset(first), relabeller(first, twin), mix, memory_senses(other, mdp))
    assert relabelled_sampler(mdp_dataset(first), relabeller(first, twin), mix).transition_count == len(first)
