"""Logs that record honest sensing (``log --sensing radio``): what a robot's own sensors read, the same moves as the
privileged log of the same seed, a name and card that say so, a Minari copy that recovers the honest env, and
trainers that refuse a log whose sensing is not theirs."""

import dataclasses

import numpy as np
import pytest

from dtradar_data.core.errors import SchemaMismatchError
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.sensing import PER_TX, Readings, honest_dim, honest_names
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-10x8"
PRIVILEGED = LogConfig(
    scene=SMALL, behaviour="noisy-shortest", steps=600, num_envs=12, max_steps=15, seed=3, minari=False, verbose=False
)
HONEST = dataclasses.replace(PRIVILEGED, sensing="radio", sensing_noise="none")


@pytest.fixture()
def stores(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return root


@pytest.fixture(scope="module")
def twin():
    return load_dataset(f"{SMALL}/blueprint")


def test_an_honest_log_records_only_the_robots_own_cell_readings_and_the_same_moves_as_a_privileged_one(stores, twin):
    honest, privileged = log_dataset(HONEST, twin), log_dataset(PRIVILEGED, twin)
    assert honest.name.endswith("/noisy-shortest-radio") and privileged.name.endswith("/noisy-shortest")
    a, p = honest.arrays(), privileged.arrays()
    for k in ("action", "cell", "target", "reward", "terminated", "truncated"):
        np.testing.assert_array_equal(a[k], p[k], err_msg=k)  # the behaviour acts the same whatever is recorded
    k = twin.transmitters
    assert a["obs"].shape[1] == honest_dim(k) and honest.meta["observations"]["names"] == list(honest_names(k))
    r = Readings.from_dataset(twin)
    cell, obs = a["cell"].astype(np.int64), a["obs"]
    per_tx = obs[:, : k * PER_TX].reshape(-1, k, PER_TX)
    # without noise every reading is its own cell's, looked up by the cell alone: nothing of another cell or of x, y
    np.testing.assert_allclose(per_tx[..., :-1], r.radio[cell], rtol=1e-6)
    np.testing.assert_array_equal(per_tx[..., -1] > 0.5, r.heard[cell])
    np.testing.assert_array_equal(obs[:, k * PER_TX : k * PER_TX + 4] > 0.5, r.blocked_around[cell])
    np.testing.assert_allclose(obs[:, -2:], r.target_xy[a["target"].astype(np.int64)])
    first = np.r_[True, a["episode"][1:] != a["episode"][:-1]]
    np.testing.assert_array_equal(obs[:, k * PER_TX + 9] > 0.5, first)  # every episode switches the robot on


def test_an_honest_logs_card_and_version_say_what_it_records(stores, twin):
    honest = log_dataset(HONEST, twin)
    card = (honest.path / "README.md").read_text()
    assert "Honest sensing `radio`" in card and "**privileged**" in card
    assert honest.meta["settings"]["sensing"] == "radio"
    privileged = log_dataset(PRIVILEGED, twin)
    assert "sensing" not in privileged.meta["settings"]  # a privileged log's version is what it was before sensings
    assert "Privileged" in (privileged.path / "README.md").read_text()


def test_an_honest_logs_minari_copy_recovers_the_honest_env(stores, twin):
    import minari

    from dtradar_rl.offline.minari_copy import export_minari

    mid = export_minari(log_dataset(HONEST, twin))
    env = minari.load_dataset(mid).recover_environment()
    assert env.spec.id.endswith("-honest-v0") and env.spec.kwargs["sensing"] == "radio"
    assert env.observation_space.shape == (honest_dim(twin.transmitters),)


def test_a_trainer_refuses_a_log_whose_sensing_is_not_its_own(stores, twin, tmp_path):
    honest = log_dataset(HONEST, twin)
    cfg = OfflineConfig(scene=SMALL, n_steps=10, eval_variants=(), out=str(tmp_path / "run"), verbose=False)
    with pytest.raises(SchemaMismatchError, match="--sensing radio"):
        train_offline(cfg, honest)


def test_medium_replay_cannot_record_honest_sensing():
    with pytest.raises(ConfigError, match="replay buffer"):
        dataclasses.replace(HONEST, behaviour="medium-replay").validate()
