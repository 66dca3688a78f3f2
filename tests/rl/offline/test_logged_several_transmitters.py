"""Offline data from a twin with two transmitters: the log holds both transmitters' observations and normaliser,
the memory window rebuilt from it is what the memory env shows along the same moves, and a tiny offline run trains
on it and acts on the twin."""

import dataclasses

import numpy as np
import pytest

from dtradar_data.core.errors import SchemaMismatchError
from dtradar_rl.envs.memory import MemoryGymEnv
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.log_settings import check_compatible
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.memory_senses import MemorySenses
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import PAPER_COLUMNS, Normalizer, obs_dim, observation_columns

#: The scene the log is named after (the twin itself is passed in: a two-transmitter synthetic twin has no name to
#: load it by).
SCENE = "synthetic-12x8"
LOG = {"scene": SCENE, "num_envs": 16, "max_steps": 20, "seed": 3}


@pytest.fixture(scope="module")
def store(tmp_path_factory, two_tx):
    """A data root of this module with a short noisy-shortest log on the two-transmitter twin."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp_path_factory.mktemp("root")))
        mp.setenv("MINARI_DATASETS_PATH", str(tmp_path_factory.mktemp("minari")))
        cfg = LogConfig(**LOG, behaviour="noisy-shortest", steps=2_000, minari=False, verbose=False)
        yield log_dataset(cfg, two_tx)


def test_a_log_of_a_twin_with_two_transmitters_holds_both_transmitters_observations(store, two_tx):
    a = store.arrays()
    names = store.meta["observations"]["names"]
    assert a["obs"].shape[1] == a["next_obs"].shape[1] == len(names) == obs_dim("neighbors", 2)
    assert "tx1_has_path" in names and store.meta["parent"] == two_tx.name
    assert tuple(store.meta["normalizer"]["columns"]) == observation_columns(two_tx)
    assert set(np.unique(a["obs"][:, names.index("tx1_has_path")])) <= {0.0, 1.0}


@pytest.mark.parametrize("bumps", [False, True])
def test_the_memory_window_rebuilt_from_a_two_transmitter_log_is_what_the_memory_env_shows(store, two_tx, bumps):
    senses = MemorySenses(store, GridMDP.from_dataset(two_tx), radius=3, bumps=bumps, visits=True)
    a = store.arrays()
    ext = senses.arrays(a)
    env = MemoryGymEnv(
        two_tx,
        obs="neighbors",
        memory_radius=3,
        memory_bumps=bumps,
        memory_visits=True,
        normalizer=Normalizer.from_dict(store.meta["normalizer"]),
        max_steps=10_000,
    )
    xy = lambda c: tuple(int(v) for v in env.mdp.xy(int(c)))  # noqa: E731
    bad, seen = [], 0
    for s in np.flatnonzero(a["step"] == 0):
        o, _ = env.reset(options={"start": xy(a["cell"][s]), "target": xy(a["target"][s])})
        i = s
        while True:
            seen += 1
            bad += [i] * (not np.array_equal(o, ext["obs"][i]))
            o, *_ = env.step(int(a["action"][i]))
            bad += [i] * (not np.array_equal(o, ext["next_obs"][i]))
            if a["terminated"][i] or a["truncated"][i]:
                break
            i += 1
    assert seen == len(a["action"]) and not bad


def test_a_tiny_offline_run_trains_on_a_two_transmitter_log_and_acts_on_the_twin(store, two_tx, tmp_path):
    cfg = OfflineConfig(
        **LOG, transitions=2_000, shortest_prob=0.3, algorithm="dqn", n_steps=10, batch_size=16, hidden=(8,),
        eval_variants=(), threads=1, verbose=False, out=str(tmp_path / "run"),
    )  # fmt: skip
    result = train_offline(cfg, dataset=two_tx)
    assert result.policy.normalizer.transmitters == 2 and result.logged["source"]
    metrics, _ = evaluate(result.policy, two_tx, pairs=10)
    assert 0.0 <= metrics.success_rate <= 1.0


def test_a_log_whose_normaliser_holds_another_count_of_transmitters_is_refused(store, two_tx):
    check_compatible(store, OfflineConfig(**LOG), two_tx)  # the log of this very twin fits
    norm = store.meta["normalizer"]
    one = {k: v[: len(PAPER_COLUMNS)] for k, v in norm.items()}  # what a one-transmitter twin's log would hold
    forged = dataclasses.replace(store, meta={**store.meta, "normalizer": one})
    with pytest.raises(SchemaMismatchError, match="normaliser holds 10 columns, the twin's 18"):
        check_compatible(forged, OfflineConfig(**LOG), two_tx)
