"""The staging folders of RT versions and Hub pulls under ``<root>/work``: a killed build's or pull's is removed by the
next build and the next pull, never one a live process holds, nor a build's resumable work folder."""

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

from dtradar_data.core.ids import DatasetId
from dtradar_data.pipeline import builder
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import hub
from dtradar_data.store import local, writing
from dtradar_data.store.staging import held_stage

V0, V1 = "0123456789abcdef", "fedcba9876543210"
DID = DatasetId("cubicle", "blueprint", None)

PUT = """
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import writing

ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
META = {**ds.meta, "rt": {"max_depth": 5}, "licence": "CC-BY-4.0"}
"""

KILLED_WRITE = PUT + textwrap.dedent("""
    import time

    real = writing._write_parquet


    def paused(*args):
        real(*args)
        print("midway", flush=True)  # the cells are in the stage: the parent kills us here
        time.sleep(60)


    writing._write_parquet = paused
    writing.write_version("cubicle/blueprint", "fedcba9876543210", ds.table, META)
""")

KILLED_PULL = textwrap.dedent("""
    import time

    from dtradar_data.publish import hub


    def paused(repo_id, revision, dest, cache):
        dest.mkdir(parents=True)
        (dest / "cells.parquet").write_bytes(b"half a download")
        print("midway", flush=True)
        time.sleep(60)


    hub._download = paused
    hub.pull("cubicle/blueprint", repo_id="me/bp")
""")


def killed(script: str) -> subprocess.Popen:
    """``script`` in a process of its own, held at ``midway`` (:func:`wait_midway`), then SIGKILLed (:func:`kill`)."""
    return subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_midway(proc: subprocess.Popen) -> None:
    """Block until ``proc`` prints ``midway`` (its stage is made and held); fail with its stderr if it ends first."""
    for line in proc.stdout:
        if line.strip() == "midway":
            return
    kill(proc)


def kill(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc`` (if still running) and check that the kill, not the process, ended it."""
    try:
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        err = proc.stderr.read()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL, f"it ended by itself ({proc.returncode}): {err[-2000:]}"


def stages(work):
    return sorted(p.name for p in work.glob("*-cubicle-blueprint-*") if p.is_dir())


def test_a_killed_builds_or_pulls_stage_is_removed_by_the_next_build_and_pull_but_never_a_live_one(
    root, tmp_path, monkeypatch
):
    # One after the other, each held while the next starts: a process that starts cleans the stages of those already
    # killed (what this test checks below), so the write, killed first, would lose its stage to a slow-starting pull.
    pull = killed(KILLED_PULL)
    wait_midway(pull)
    try:
        write = killed(KILLED_WRITE)
        wait_midway(write)
        kill(write)
    finally:
        kill(pull)  # never left sleeping, even when the write failed
    work = root / "work"
    left = stages(work)
    assert [n.split("-")[0] for n in left] == ["pull", "stage"], f"each killed process left its stage: {left}"
    assert all((work / f"{n}.lock").is_file() for n in left)

    resumable = work / "cubicle" / "blueprint" / V1  # a build's finished trace batches: kept for its resume
    resumable.mkdir(parents=True)
    (resumable / "batch_00000.npz").write_bytes(b"traced")
    legacy = work / f"stage-cubicle-blueprint-{V1}-abc12345"  # an older dtradar's lockless stage, hours old
    legacy.mkdir()
    (legacy / "cells.parquet").write_bytes(b"partial")
    hours_ago = time.time() - 7200
    for p in (legacy / "cells.parquet", legacy):
        os.utime(p, (hours_ago, hours_ago))
    monkeypatch.setattr(builder, "build_static", lambda config: [])  # the build's start, without tracing

    with held_stage(work, writing.stage_prefix(DID, V0)) as live:  # a live writer's stage, there all along
        (live / "cells.parquet").write_bytes(b"a live writer's")
        builder.build(BuildConfig(scene="cubicle", progress=False))
        assert stages(work) == [live.name], "the next build removed the killed ones' stages, not the live one"
        assert sorted(p.name for p in resumable.iterdir()) == ["batch_00000.npz"]

        # what a pull killed under this code leaves (its lock free), removed by the next pull
        stale = work / f"pull-cubicle-blueprint-{'x' * 8}"
        (stale / "download").mkdir(parents=True)
        (work / f"{stale.name}.lock").touch()
        ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
        served = tmp_path / "served"
        shutil.copytree(writing.write_version("cubicle/blueprint", V1, ds.table, {**ds.meta, "rt": {}}), served)
        shutil.rmtree(root / "datasets")
        monkeypatch.setattr(hub, "_download", lambda repo_id, revision, dest, cache: shutil.copytree(served, dest))
        assert hub.pull("cubicle/blueprint", repo_id="me/bp").name == V1
        assert local.load("cubicle/blueprint").version == V1
        assert stages(work) == [live.name] and (live / "cells.parquet").is_file(), "a live process's stage is kept"
    assert writing.clean_stages() == [], "a stage is removed on the way out of its block"
    assert sorted(p.name for p in work.iterdir()) == ["cubicle"], "no folder and no lock file left"
