"""A log too large for this machine's memory is refused when its config is validated, before any twin is loaded or
step rolled out, giving the size, what is available and the --steps that fit."""

import pytest

from dtradar_rl.cli import main
from dtradar_rl.offline import collection, logged
from dtradar_rl.offline.behaviours import BehaviourSpec
from dtradar_rl.offline.collection import roll, rollout_bytes, rollout_steps
from dtradar_rl.offline.logged import LogConfig, LogTooLargeError, log_dataset
from dtradar_rl.task.observations import obs_dim
from dtradar_rl.task.twins import load_dataset

GIB = 2**30


@pytest.fixture()
def sixteen_gib(monkeypatch):
    monkeypatch.setattr(logged, "available_memory", lambda: 16 * GIB)


def test_a_log_of_a_hundred_billion_steps_is_refused_up_front_naming_its_size_the_memory_and_fewer_steps(
    root, sixteen_gib, capsys
):
    argv = ["log", "--scene", "cubicle", "--behaviour", "explore", "--steps", "100000000000"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--steps 100000000000" in err and "16.0 GiB available" in err
    assert "how to fix: log fewer --steps (about" in err
    assert "not built" not in err  # refused before the twin is looked for
    assert not root.exists()


def test_a_log_that_fits_is_not_refused(sixteen_gib):
    assert LogConfig(scene="cubicle", steps=100_000).validate().steps == 100_000


def test_memory_is_not_checked_where_the_system_does_not_say(monkeypatch):
    monkeypatch.setattr(logged, "available_memory", lambda: None)
    LogConfig(scene="cubicle", steps=10**11).validate()


def test_medium_replay_logs_no_steps_of_its_own_so_its_steps_are_not_counted(sixteen_gib):
    LogConfig(scene="cubicle", behaviour="medium-replay", steps=10**11).validate()


def test_the_estimate_counts_every_column_the_rollout_holds_at_the_observation_width():
    ds = load_dataset("synthetic-10x8/blueprint")
    r = roll(ds, BehaviourSpec("random"), steps=100, num_envs=12, obs="neighbors")
    assert len(r.columns["obs"]) == rollout_steps(100, 12) == 108
    held = sum(c.nbytes for c in r.columns.values())
    recorded = sum(c.nbytes for k, c in r.columns.items() if k not in collection.ASSEMBLED_BYTES)
    assert rollout_bytes(100, 12, obs_dim("neighbors")) == held + recorded  # recorded steps stacked while held


def test_a_twin_with_wider_observations_is_checked_again_before_anything_is_rolled_out(root, two_tx, monkeypatch):
    cfg = LogConfig(scene="synthetic-tx2-12x8", steps=1000, num_envs=10, minari=False, verbose=False)
    narrow, wide = (rollout_bytes(1000, 10, obs_dim("neighbors", k)) for k in (1, 2))
    monkeypatch.setattr(logged, "available_memory", lambda: (narrow + wide) // 2)
    monkeypatch.setattr(logged, "roll", lambda *a, **k: pytest.fail("rolled out a log that does not fit"))
    cfg.validate()  # the narrowest twin's observations fit
    with pytest.raises(LogTooLargeError, match="--steps 1000: logging 1,000 steps of 57-column"):
        log_dataset(cfg, two_tx)
    assert not root.exists()
