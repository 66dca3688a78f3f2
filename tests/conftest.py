"""Shared fixtures: every test that touches the store gets its own empty data root."""

import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest


@pytest.fixture()
def root(tmp_path, monkeypatch):
    """An empty data root (``DTRADAR_DATA_ROOT``) under the test's temporary folder."""
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "root"))
    return tmp_path / "root"


@pytest.fixture()
def read_only(root):
    """``read_only()``: the data root (``root``, with what the test stored in it) made read-only, as a shared mirror
    or a container image is (``chmod -R a-w``); writable again after the test. The test is skipped where that does
    not stop writes (run as root, which writes anyway)."""
    made = []

    def make() -> Path:
        root.mkdir(parents=True, exist_ok=True)
        subprocess.run(["chmod", "-R", "a-w", str(root)], check=True)
        made.append(root)
        if os.access(root, os.W_OK):
            pytest.skip("chmod does not make a folder read-only for this user (root)")
        return root

    yield make
    for folder in made:
        subprocess.run(["chmod", "-R", "u+w", str(folder)], check=True)


#: A user's 2 m x 1.5 m room file with one box: the smallest scene the tracer builds in seconds.
TINY_ROOM = """
format = 1
[scene]
name = "tiny-room"
title = "Tiny room"
description = "A user's own 2 m x 1.5 m room with one box"
source = "test"
licence = "CC0-1.0"
attribution = "nobody"
[room]
width_m = 2.0
length_m = 1.5
height_m = 2.5
wall_thickness_m = 0.2
wall_material = "brick"
floor_material = "concrete"
floor_thickness_m = 0.1
ceiling_material = "concrete"
ceiling_thickness_m = 0.1
[grid]
cell_m = 0.5
nx = 4
ny = 3
[tx]
position_m = [1.0, 0.75, 2.4]
[robot]
rx_height_m = 1.0
robot_height_m = 1.0
[[objects]]
name = "box_01"
kind = "box"
material = "wood"
x_m = 0.25
y_m = 0.25
width_m = 0.4
length_m = 0.4
height_m = 0.8
"""


@pytest.fixture()
def tiny_room() -> str:
    """The text of a tiny user's room file (``TINY_ROOM``), for tests that read or trace a scene file."""
    return TINY_ROOM


class PausedProcess:
    """A Python script run in a process of its own (``python -c script args...``), which a test lets run up to a line
    it prints (:meth:`wait_for`: the script pauses there, e.g. in a ``time.sleep`` it patched in), then acts beside it
    or SIGKILLs it (:meth:`kill`). stdout is read line by line in a thread, so a wait has a timeout; stderr goes to a
    file, shown when the script ends early."""

    def __init__(self, script: str, args, stderr_path):
        self._stderr_path = stderr_path
        self._stderr = open(stderr_path, "w")
        self.proc = subprocess.Popen(
            [sys.executable, "-c", script, *map(str, args)], stdout=subprocess.PIPE, stderr=self._stderr, text=True
        )
        self.lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def stderr(self) -> str:
        self._stderr.flush()
        return open(self._stderr_path).read()

    def wait_for(self, line: str, timeout: float = 120.0) -> None:
        """Return once the script has printed ``line``; fail the test when it ends or takes longer first."""
        deadline = time.monotonic() + timeout
        try:
            while (got := self.lines.get(timeout=max(0.0, deadline - time.monotonic()))) is not None:
                if got.strip() == line:
                    return
        except queue.Empty:
            raise AssertionError(f"no line {line!r} within {timeout:g} s: {self.stderr()[-3000:]}") from None
        self.proc.wait(timeout=30)
        raise AssertionError(f"it ended ({self.proc.returncode}) before printing {line!r}: {self.stderr()[-3000:]}")

    def kill(self) -> None:
        """SIGKILL it (``kill -9``: nothing of it runs after) and check that the kill is what ended it."""
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=30)
        assert self.proc.returncode == -signal.SIGKILL, f"it ended by itself ({self.proc.returncode})"

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.proc.stdout.close()
        self._stderr.close()


@pytest.fixture()
def paused_process(tmp_path):
    """``start(script, *args)`` -> a :class:`PausedProcess`; every one still running at the test's end is killed."""
    if not hasattr(signal, "SIGKILL"):
        pytest.skip("needs SIGKILL")
    started: list[PausedProcess] = []

    def start(script: str, *args) -> PausedProcess:
        started.append(PausedProcess(script, args, tmp_path / f"stderr-{len(started)}.txt"))
        return started[-1]

    yield start
    for p in started:
        p.close()


def pytest_sessionfinish(session, exitstatus):
    session.config._dtradar_exitstatus = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """End the process once pytest has reported. The native libraries the tests load (Dr.Jit's LLVM backend, torch's
    thread pools, Ray's client) have crashed the interpreter while it tore them down after the last test: a
    segmentation fault in 2 of 6 full runs on this machine, every test passed, no Python frame in the crash.
    Nothing of the tests' results is left to write at this point."""
    status = getattr(config, "_dtradar_exitstatus", None)
    if status is None:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
