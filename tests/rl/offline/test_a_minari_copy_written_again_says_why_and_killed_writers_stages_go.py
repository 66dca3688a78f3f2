"""The Minari copies are checked for content as the solve cache is: a copy whose files differ from the sha256 its
record holds is written again *and says so* (it was rewritten silently), and the staging folder a killed writer left
in the Minari folder (as large as its copy) is removed, saying so, by the next export once its lock is free, even when
that export finds its own copy complete (the killed writer may have been another copy's, never written again). A
stage held by a live writer stays."""

import numpy as np
import pytest

from dtradar_data.store import held_stage
from dtradar_data.store import logged as T
from dtradar_rl.offline import minari_copy

minari = pytest.importorskip("minari")
pytestmark = pytest.mark.filterwarnings("ignore:the Minari copy .* records no env spec:UserWarning")  # no twin here

NAME = "tiny/blueprint/noisy-shortest"
MID = "dtradar/tiny-blueprint-noisy-shortest-v0"


def put(n_episodes=3, length=4, dim=5):
    rng = np.random.default_rng(0)
    parts = {k: [] for k in ("obs", "next_obs", "terminated", "truncated", "episode", "step")}
    for e in range(n_episodes):
        o = rng.normal(size=(length + 1, dim)).astype(np.float32)
        parts["obs"].append(o[:-1])
        parts["next_obs"].append(o[1:])
        parts["terminated"].append(np.r_[np.zeros(length - 1, bool), True])
        parts["truncated"].append(np.zeros(length, bool))
        parts["episode"].append(np.full(length, e))
        parts["step"].append(np.arange(length))
    n = n_episodes * length
    table = T.transitions_table(
        **{k: np.concatenate(v) for k, v in parts.items()},
        action=rng.integers(0, 4, n), reward=rng.normal(size=n), robot=np.zeros(n), cell=np.arange(n),
        target=np.full(n, 7),
    )  # fmt: skip
    inputs = T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="0123456789abcdef",
        behaviour={"kind": "noisy-shortest", "shortest_prob": 0.5},
        steps=n,
        seed=0,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": length},
        libraries={"numpy": "x"},
    )
    T.write_logged(NAME, inputs, table, {"behaviour_text": "test"})
    return T.load_logged(NAME)


@pytest.fixture()
def minari_root(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return tmp_path / "minari"


def test_a_damaged_copy_is_written_again_naming_why(minari_root, capsys):
    logged = put()
    assert minari_copy.export_minari(logged) == MID
    assert capsys.readouterr().err == "", "a first copy says nothing"
    f = minari_root / MID / "data" / "main_data.hdf5"
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    assert minari_copy.export_minari(logged) == MID
    err = capsys.readouterr().err
    assert f"the Minari copy {MID} cannot be used" in err and "recorded sha256" in err and "writing it again" in err
    assert minari_copy.copy_state(minari_root / MID, logged)[0] == "complete"
    assert minari_copy.export_minari(logged) == MID
    assert capsys.readouterr().err == "", "a sound copy is served silently"


def killed_stage(minari_root, name="abcd1234"):
    """What a writer killed with SIGKILL leaves: its stage folder (a part of a copy) and the stage's lock file, which
    nobody holds any more."""
    stage = minari_root / f"{minari_copy.STAGE_PREFIX}{name}"
    (stage / "dtradar" / "other-copy-v0" / "data").mkdir(parents=True)
    (stage / "dtradar" / "other-copy-v0" / "data" / "main_data.hdf5").write_bytes(b"\0" * 4096)
    stage.with_name(stage.name + ".lock").touch()
    return stage


def test_a_killed_writers_stage_goes_when_its_lock_is_free_beside_a_complete_copy(minari_root, capsys):
    logged = put()
    minari_copy.export_minari(logged)
    capsys.readouterr()
    stage = killed_stage(minari_root)
    assert minari_copy.export_minari(logged) == MID, "the copy itself is complete: served as it is"
    err = capsys.readouterr().err
    assert not stage.exists() and not stage.with_name(stage.name + ".lock").exists()
    assert f"removed what a killed Minari write left in {minari_root}: {stage.name}" in err, err
    assert minari_copy.copy_state(minari_root / MID, logged)[0] == "complete"


def test_a_live_writers_stage_stays(minari_root, capsys):
    logged = put()
    minari_copy.export_minari(logged)
    with held_stage(minari_root, minari_copy.STAGE_PREFIX) as live:
        (live / "partial").write_bytes(b"x")
        assert minari_copy.export_minari(logged) == MID
        assert (live / "partial").is_file(), "a stage held by a live writer is never removed"
    assert "removed" not in capsys.readouterr().err
