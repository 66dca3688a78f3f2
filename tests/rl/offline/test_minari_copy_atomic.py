"""The Minari copy of a logged dataset is whole or absent, and the store's staging is cleaned: a writer killed with
SIGKILL in the middle of the copy leaves no copy (the next export writes a whole one), a copy found incomplete or
damaged in place is rewritten rather than reused, two processes writing the same copy both succeed (the second waits
on a lock that says what it waits for), two data roots never share a copy, a killed log leaves a staging folder the
next write removes (only when no live process holds it), and the command a damaged version's hint gives logs that
version again. Real processes (``kill -9``) on tiny synthetic tables; one full ``log`` race is marked slow."""

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from dtradar_data.store import logged as T
from dtradar_rl.offline import minari_copy
from dtradar_rl.task.config import ConfigError

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
minari = pytest.importorskip("minari")

NAME = "tiny/blueprint/noisy-shortest"
MID = "dtradar/tiny-blueprint-noisy-shortest-v0"


def columns(n_episodes=3, length=4, dim=5, seed=0):
    rng = np.random.default_rng(seed)
    parts = {k: [] for k in ("obs", "next_obs", "terminated", "truncated", "episode", "step")}
    for e in range(n_episodes):
        o = rng.normal(size=(length + 1, dim)).astype(np.float32)
        parts["obs"].append(o[:-1])
        parts["next_obs"].append(o[1:])
        last = e == n_episodes - 1
        parts["terminated"].append(np.r_[np.zeros(length - 1, bool), not last])
        parts["truncated"].append(np.r_[np.zeros(length - 1, bool), last])
        parts["episode"].append(np.full(length, e))
        parts["step"].append(np.arange(length))
    n = n_episodes * length
    return {
        **{k: np.concatenate(v) for k, v in parts.items()},
        "action": rng.integers(0, 4, n),
        "reward": rng.normal(size=n),
        "robot": np.zeros(n),
        "cell": np.arange(n),
        "target": np.full(n, 7),
    }


def put(seed=0, n_episodes=3):
    inputs = T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="0123456789abcdef",
        behaviour={"kind": "noisy-shortest", "shortest_prob": 0.5},
        steps=4 * n_episodes,
        seed=seed,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": 4},
        libraries={"numpy": "x"},
    )
    table = T.transitions_table(**columns(n_episodes, seed=seed))
    T.write_logged(NAME, inputs, table, {"behaviour_text": "test"})
    return T.load_logged(NAME)


@pytest.fixture()
def stores(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    return root


def assert_whole(logged, mid=MID):
    """The copy is there (in $MINARI_DATASETS_PATH), holds every logged transition and is recorded complete."""
    m = minari.load_dataset(mid)
    assert (m.total_episodes, m.total_steps) == (logged.meta["stats"]["episodes"], len(logged))
    back = minari_copy.from_minari(mid)
    for k, v in back.items():
        np.testing.assert_array_equal(v, logged.arrays()[k], err_msg=k)
    assert minari_copy.copy_state(Path(os.environ["MINARI_DATASETS_PATH"]) / mid, logged)[0] == "complete"


def run(script: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", script, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def finish(procs: dict[str, subprocess.Popen], timeout: float = 120) -> dict[str, tuple[int, str, str]]:
    out = {}
    try:
        for role, proc in procs.items():
            stdout, stderr = proc.communicate(timeout=timeout)
            out[role] = (proc.returncode, stdout, stderr)
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return out


def kill_at(proc: subprocess.Popen, line: str) -> None:
    """SIGKILL ``proc`` once it prints ``line`` (it pauses right after)."""
    try:
        for got in proc.stdout:
            if got.strip() == line:
                proc.send_signal(signal.SIGKILL)
                break
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL, f"it ended by itself ({proc.returncode}) before {line!r}"


# ------------------------------------------------------------------------------------------------ kill -9


KILLED_EXPORT = textwrap.dedent("""
    import sys
    import time

    from minari.dataset._storages import hdf5_storage

    from dtradar_rl.offline.minari_copy import export_minari

    real = hdf5_storage.HDF5Storage.update_episodes


    def paused(self, episodes):
        print("midway", flush=True)  # Minari's metadata is written, no episode yet: the parent kills us here
        time.sleep(60)
        return real(self, episodes)


    hdf5_storage.HDF5Storage.update_episodes = paused
    export_minari(sys.argv[1])
""")


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_minari_copy_killed_mid_write_is_absent_and_the_next_export_writes_a_whole_one(stores):
    logged = put()
    kill_at(run(KILLED_EXPORT, NAME), "midway")
    root = stores.parent / "minari"
    assert not (root / MID).exists(), "a killed write leaves no copy under the id (it left 0 episodes there)"
    assert [p.name for p in root.glob(".dtradar-stage-*") if p.is_dir()], "what it wrote is in a hidden stage"
    assert minari_copy.export_minari(logged) == MID
    assert_whole(logged)
    assert not [p for p in root.glob(".dtradar-stage-*") if p.is_dir()], "the killed writer's stage is removed"
    assert MID in minari.list_local_datasets()


def zero_episodes(folder):
    """What a write killed after Minari's metadata left before staging existed: a copy with no episode."""
    (folder / minari_copy.RECORD_FILE).unlink()
    (folder / "data" / "main_data.hdf5").unlink()
    meta = json.loads((folder / "data" / "metadata.json").read_text())
    (folder / "data" / "metadata.json").write_text(json.dumps({**meta, "total_episodes": 0, "total_steps": 0}))


def flipped_byte(folder):
    f = folder / "data" / "main_data.hdf5"
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))


def fewer_episodes(folder):
    meta = json.loads((folder / "data" / "metadata.json").read_text())
    (folder / "data" / "metadata.json").write_text(json.dumps({**meta, "total_episodes": 1}))


def no_record(folder):
    (folder / minari_copy.RECORD_FILE).unlink()


@pytest.mark.parametrize("damage", [zero_episodes, flipped_byte, fewer_episodes, no_record])
def test_a_copy_found_incomplete_or_damaged_in_place_is_rewritten_not_reused(stores, damage):
    logged = put()
    minari_copy.export_minari(logged)
    folder = stores.parent / "minari" / MID
    damage(folder)
    assert minari_copy.export_minari(logged) == MID
    assert_whole(logged)


def test_a_copy_of_another_version_that_no_data_root_holds_any_more_is_replaced(stores):
    old = put(seed=0)
    minari_copy.export_minari(old)
    shutil.rmtree(T.logged_root())  # the store is emptied: its next v0 is another version
    new = put(seed=1, n_episodes=2)
    assert new.tag == "v0" and new.version != old.version
    minari_copy.export_minari(new)
    assert_whole(new)


# -------------------------------------------------------------------------------------------- data roots


def test_two_data_roots_write_their_copies_apart_and_a_shared_minari_folder_is_refused_cleanly(tmp_path, monkeypatch):
    monkeypatch.delenv("MINARI_DATASETS_PATH", raising=False)
    logged = {}
    for name, seed in (("a", 0), ("b", 1)):
        monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / name))
        logged[name] = put(seed=seed)
        assert minari_copy.export_minari(logged[name]) == MID  # both are v0 of their own root
        assert (tmp_path / name / "minari" / MID / "data").is_dir(), "in the data root's own Minari folder"
        assert minari_copy.copy_state(tmp_path / name / "minari" / MID, logged[name])[0] == "complete"
        np.testing.assert_array_equal(minari_copy.load_minari(logged[name]).total_steps, len(logged[name]))

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "shared"))
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "a"))
    minari_copy.export_minari(logged["a"])
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "b"))
    with pytest.raises(ConfigError) as e:
        minari_copy.export_minari(logged["b"])
    text = f"{e.value.message} {e.value.hint}"
    assert str(tmp_path / "a") in e.value.message, "it names the data root that holds the copy"
    assert "MINARI_DATASETS_PATH" in e.value.hint and "--no-minari" in e.value.hint
    assert "overwrite" not in text and "delete_dataset" not in text, "no Python argument the CLI does not have"
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "a"))
    assert_whole(logged["a"])  # root a's copy is untouched


# ---------------------------------------------------------------------------------------------------- race


RACER = textwrap.dedent("""
    import sys
    import time
    from pathlib import Path

    import minari

    from dtradar_rl.offline import minari_copy

    role, signals, name = sys.argv[1], Path(sys.argv[2]), sys.argv[3]


    def wait_for(flag):
        deadline = time.monotonic() + 60
        while not (signals / flag).exists():
            if time.monotonic() > deadline:
                sys.exit(f"{role}: gave up waiting for {flag}")
            time.sleep(0.02)


    real = minari.create_dataset_from_buffers


    def first_writes_slowly(*args, **kwargs):
        (signals / "first-writing").touch()
        wait_for("second-exporting")
        time.sleep(1.0)  # the second reaches the copy meanwhile
        return real(*args, **kwargs)


    if role == "first":
        minari.create_dataset_from_buffers = first_writes_slowly
    else:
        wait_for("first-writing")
        (signals / "second-exporting").touch()
    print(f"{role} done: {minari_copy.export_minari(name)}", flush=True)
""")


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_two_processes_writing_the_same_copy_both_succeed_and_the_second_says_what_it_waits_for(stores, tmp_path):
    logged = put()
    signals = tmp_path / "signals"
    signals.mkdir()
    procs = {role: run(RACER, role, str(signals), NAME) for role in ("first", "second")}
    out = finish(procs)
    for role, (rc, stdout, stderr) in out.items():
        assert rc == 0, f"{role} failed:\n{stdout}\n{stderr[-3000:]}"
        assert f"{role} done: {MID}" in stdout
    pid = procs["first"].pid
    waited = out["second"][2]
    assert f"waiting for pid {pid}" in waited and f"which is writing the Minari copy {MID}" in waited
    assert_whole(logged)
    assert [p.name for p in (stores.parent / "minari" / "dtradar").iterdir() if p.is_dir()] == [MID.split("/")[1]]


LOG = textwrap.dedent("""
    import sys
    import time
    from pathlib import Path

    from dtradar_rl import cli
    from dtradar_rl.offline import logged

    role, signals = sys.argv[1], Path(sys.argv[2])


    def wait_for(flag):
        deadline = time.monotonic() + 120
        while not (signals / flag).exists():
            if time.monotonic() > deadline:
                sys.exit(f"{role}: gave up waiting for {flag}")
            time.sleep(0.02)


    real = logged.write_logged


    def first_stores_slowly(*args, **kwargs):
        (signals / "first-storing").touch()
        wait_for("second-started")
        time.sleep(3.0)  # the second reaches the same version meanwhile
        return real(*args, **kwargs)


    if role == "first":
        logged.write_logged = first_stores_slowly
    else:
        wait_for("first-storing")
        (signals / "second-started").touch()
    sys.exit(cli.main(["log", "--scene", "synthetic-10x8", "--steps", "120", "--num-envs", "12", "--max-steps", "15"]))
""")


@pytest.mark.slow
def test_two_identical_log_commands_at_once_both_succeed_with_one_version_and_one_whole_copy(stores, tmp_path):
    signals = tmp_path / "signals"
    signals.mkdir()
    out = finish({role: run(LOG, role, str(signals)) for role in ("first", "second")}, timeout=300)
    for role, (rc, stdout, stderr) in out.items():
        assert rc == 0, f"{role} failed:\n{stdout}\n{stderr[-3000:]}"
    assert "which is logging synthetic-10x8/blueprint/noisy-shortest@" in out["second"][2]
    assert "already logged with these settings: reused" in out["second"][1], "rolled out once, by the first"
    name = "synthetic-10x8/blueprint/noisy-shortest"
    assert len(T.local_versions(T.parse_logged_id(name), damaged=True)) == 1
    assert_whole(T.load_logged(name), "dtradar/synthetic-10x8-blueprint-noisy-shortest-v0")
    assert not list((stores / "work").glob("logged-*"))


# ------------------------------------------------------------------------------------------------ staging


KILLED_WRITE = textwrap.dedent("""
    import sys
    import time

    import pyarrow.parquet as pq

    from dtradar_data.store import logged as T
    from dtradar_data.store.logged import local

    real = pq.write_table


    def paused(*args, **kwargs):
        real(*args, **kwargs)
        print("midway", flush=True)  # the table is in the staging folder: the parent kills us here
        time.sleep(60)


    local.pq.write_table = paused
    table = T.read_transitions(T.load_logged(sys.argv[1]).path / T.TRANSITIONS_FILE)
    meta = T.load_logged(sys.argv[1]).meta
    T.write_logged(sys.argv[1], {**meta["inputs"], "seed": 7}, table, {})
""")

HOLDER = textwrap.dedent("""
    import time
    from dtradar_data.core import layout
    from dtradar_data.store.logged.staging import held_stage

    with held_stage(layout.work_root(), "logged-") as stage:
        (stage / "partial").write_text("a live writer's")
        print(stage, flush=True)
        time.sleep(60)
""")


def test_a_killed_log_leaves_a_staging_folder_that_the_next_write_removes_but_never_a_live_one(stores):
    logged = put()
    work = stores / "work"
    holder = run(HOLDER)  # a live writer's stage, there all along
    try:
        live = holder.stdout.readline().strip()
        assert live and os.path.isdir(live)
        kill_at(run(KILLED_WRITE, NAME), "midway")
        killed = [p for p in work.glob("logged-*") if p.is_dir() and str(p) != live]
        assert killed and (killed[0] / T.TRANSITIONS_FILE).is_file(), "the killed write left its stage"
        assert os.path.isdir(live), "the killed writer's own cleanup kept the live stage"
        T.write_logged(NAME, {**logged.meta["inputs"], "seed": 8}, logged.table, {})
        assert not killed[0].exists(), "the next write removed the killed one's stage"
        assert os.path.isdir(live) and (Path(live) / "partial").is_file(), "a stage held by a live process is kept"
        assert T.clean_logged_stages() == []
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
        holder.stderr.close()
    assert [str(p) for p in T.clean_logged_stages()] == [live], "once its process is gone, it is stale"
    assert not list(work.glob("logged-*")), "no folder and no lock file left"


def test_a_stage_left_by_an_older_dtradar_without_a_lock_file_is_stale_but_no_other_writers_folder(stores):
    logged = put()
    work = stores / "work"
    legacy = work / "logged-abc12345"  # tempfile.mkdtemp(prefix="logged-") of an older dtradar: no lock beside it
    legacy.mkdir(parents=True)
    (legacy / T.TRANSITIONS_FILE).write_bytes(b"partial")
    old_pull = work / "pull-logged-xyz_7890"
    (old_pull / "download").mkdir(parents=True)
    scene_work = work / "logged-room" / "blueprint" / "0123456789abcdef"  # a ray-tracing build of scene logged-room
    scene_work.mkdir(parents=True)
    lookalike = work / "logged-abcdefgh" / "blueprint"  # ... and of a scene whose name has a stage's shape
    lookalike.mkdir(parents=True)
    T.write_logged(NAME, {**logged.meta["inputs"], "seed": 9}, logged.table, {})
    assert not legacy.exists() and not old_pull.exists()
    assert scene_work.is_dir() and lookalike.is_dir(), "another writer's folder is never removed"
    assert sorted(p.name for p in work.iterdir()) == ["logged-abcdefgh", "logged-room"]


# ------------------------------------------------------------------------------------------------ re-log


def test_the_command_a_damaged_versions_hint_gives_logs_that_version_again_and_replaces_it(stores):
    from dtradar_rl import cli
    from dtradar_rl.offline.logged import LogConfig, log_dataset

    name = "synthetic-10x8/blueprint/noisy-shortest"
    cfg = LogConfig(scene="synthetic-10x8", steps=120, num_envs=12, max_steps=15, seed=2, minari=False, verbose=False)
    first = log_dataset(cfg)
    f = first.path / T.TRANSITIONS_FILE
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    with pytest.raises(Exception) as e:
        T.load_logged(name)
    command = e.value.hint.split("`")[1]
    assert command.startswith("python -m dtradar_rl log ") and "make dataset" not in e.value.hint
    assert cli.main([*shlex.split(command)[3:], "--no-minari", "--no-verbose"]) == 0
    again = T.load_logged(name)
    assert (again.version, again.tag) == (first.version, "v0"), "the same settings: the same version, replaced"
    assert again.table.equals(first.table)
    assert not list((stores / "work").glob("logged-*"))
