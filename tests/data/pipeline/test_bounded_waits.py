"""No wait is silent: a build that waits for another process's build of the same version (or a store that waits for
another store of the same dataset) says on stderr whom it waits for (pid), for what, and that Ctrl-C is safe, and
says again, with that build's progress, while it keeps waiting. (No ray tracer: the lock is held by the test, and
what the build does once it has the lock is replaced.)"""

import os
import threading
import time

import pytest

from dtradar_data.core import files
from dtradar_data.core.files import waiting_lock
from dtradar_data.core.layout import dataset_dir, work_root
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import static_build, storing
from dtradar_data.pipeline.batches import batch_dir, batch_layout
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.inputs import build_inputs
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store import versions, writing

BOUND_S = 20.0


def wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + BOUND_S
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(0.02)


def in_thread(fn):
    """Run ``fn`` in a thread; returns ``(thread, box)`` with ``box["result"]`` or ``box["error"]`` once done."""
    box = {}

    def run():
        try:
            box["result"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, box


class Stderr:
    """What the threads printed to stderr so far (capsys keeps one buffer for every thread)."""

    def __init__(self, capsys):
        self.capsys, self.text = capsys, ""

    def __call__(self) -> str:
        self.text += self.capsys.readouterr().err
        return self.text


@pytest.fixture
def spec(tmp_path, tiny_room):
    path = tmp_path / "room.toml"
    path.write_text(tiny_room)
    return load_scene_spec(str(path), "blueprint")


@pytest.fixture
def config():
    return BuildConfig(
        scene="tiny", coverage_map=False, progress=False, rt=RTSettings(max_depth=1, batch_size=4, device="cpu")
    )


def test_a_build_waiting_for_another_build_of_its_version_says_whom_it_waits_for_and_how_far_that_one_is(
    root, spec, config, capsys, monkeypatch
):
    monkeypatch.setattr(files, "LOCK_NOTICE_EVERY_S", 0.2)
    monkeypatch.setattr(storing, "write_new_version", lambda *args: "traced once the lock was free")
    version = versions.version_id(build_inputs(spec, scene_config(config, spec)))
    work = work_root() / spec.scene / spec.variant / version
    lock = work.parent / f"{version}.lock"
    stderr = Stderr(capsys)
    with waiting_lock(lock, f"building {spec.name} version {version}"):  # "another build", holding the version
        thread, box = in_thread(lambda: static_build.build_one(spec, config))
        wait_for(lambda: "waiting for" in stderr(), "the waiting message")
        first = stderr().splitlines()[0]
        assert f"pid {os.getpid()}" in first and version in first and "Ctrl-C is safe" in first
        assert "reuses" in first, "it says what happens once the other build is done"
        rt = scene_config(config, spec).rt
        where = batch_dir(work, rt, batch_layout(int((~occupancy(spec)).sum()), rt))
        where.mkdir(parents=True)
        (where / "batch_00000.npz").write_bytes(b"")  # the other build has finished its first batch
        wait_for(lambda: "finished 1 of 3 trace batches" in stderr(), "a progress line")
        assert thread.is_alive(), "it waits while the lock is held"
    thread.join(BOUND_S)
    assert not thread.is_alive() and box == {"result": "traced once the lock was free"}
    assert "still waiting for pid" in stderr() and "the lock is free" in stderr()
    assert not lock.with_name(lock.name + ".holder").exists(), "the holder's note goes with the lock"


def test_a_build_that_gets_its_lock_at_once_prints_no_waiting_line(root, spec, config, capsys, monkeypatch):
    monkeypatch.setattr(storing, "write_new_version", lambda *args: "traced")
    assert static_build.build_one(spec, config) == "traced"
    assert "waiting" not in capsys.readouterr().err


def test_a_store_waiting_for_another_store_of_the_dataset_says_so_after_a_moment(root, capsys):
    ds = synthetic_dataset(name="cubicle/blueprint")
    stderr = Stderr(capsys)
    with waiting_lock(dataset_dir("cubicle", "blueprint") / ".lock", "storing a version of cubicle/blueprint"):
        thread, box = in_thread(lambda: writing.write_version("cubicle/blueprint", "e" * 16, ds.table, ds.meta))
        wait_for(lambda: "waiting for" in stderr(), "the waiting message")
        assert f"pid {os.getpid()}" in stderr() and "storing a version of cubicle/blueprint" in stderr()
        assert thread.is_alive()
    thread.join(BOUND_S)
    assert not thread.is_alive() and "error" not in box
    assert (box["result"] / "meta.json").is_file()
