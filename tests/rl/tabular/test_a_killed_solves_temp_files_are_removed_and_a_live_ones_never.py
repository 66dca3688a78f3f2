"""A solve killed while it writes its cache leaves a temp file beside the cache file (``.q.npy.<random>.tmp``, as
large as Q*); the next process that writes that cache folder, holding its lock, removes it and says so, and a sound
cache found beside such debris has it removed when the lock is free. A temp file of a live writer (the lock held) is
never touched: a second solve of the same folder waits for the writer instead."""

import threading
import time

import numpy as np
import pytest

from dtradar_rl.tabular import cache
from dtradar_rl.tabular.cache import solve_twin
from dtradar_rl.task.twins import load_dataset

NAME = "synthetic-10x6/blueprint"

#: ``solve_twin`` that pauses (and is killed) once it has started writing Q* into the cache: its temp file is there.
WRITER = """
import sys
import time

from dtradar_rl.tabular import cache, solver
from dtradar_rl.task.twins import load_dataset


def paused(self, rows=None):
    print("midway", flush=True)
    time.sleep(120)


solver.Solution.q = paused
cache.solve_twin(load_dataset(sys.argv[1]), "geodesic", 0.9)
"""

#: A live writer of the cache folder ``argv[1]``: it holds the folder's lock and pauses.
HOLDER = """
import sys
import time
from pathlib import Path

from dtradar_data.core.files import waiting_lock
from dtradar_rl.tabular import cache

with waiting_lock(Path(sys.argv[1]) / cache.LOCK, "writing a solution"):
    print("midway", flush=True)
    time.sleep(120)
"""


def temps(folder):
    return sorted(p.name for p in folder.glob(".*.tmp"))


def folder_of(ds):
    return cache.cache_dir(ds, "geodesic", 0.9)


@pytest.mark.slow  # a solve in a worker process, killed: seconds (make test-all)
def test_the_temp_file_of_a_killed_solve_is_removed_by_the_next_writer(root, paused_process):
    ds = load_dataset(NAME)
    writer = paused_process(WRITER, NAME)
    writer.wait_for("midway")
    writer.kill()
    folder = folder_of(ds)
    left = temps(folder)
    assert len(left) == 1 and left[0].startswith(".q.npy.")

    said = []
    sol, got, cached = solve_twin(ds, "geodesic", 0.9, say=said.append)
    assert got == folder and not cached
    assert temps(folder) == [], "the killed writer's temp file is gone"
    assert len(said) == 1 and f"removed what a killed solve left in {folder}: {left[0]}" in said[0]
    assert solve_twin(ds, "geodesic", 0.9)[2], "and the cache it wrote is sound"


def test_a_sound_cache_beside_a_killed_writers_temp_file_is_served_and_the_temp_file_removed(root):
    ds = load_dataset(NAME)
    _, folder, _ = solve_twin(ds, "geodesic", 0.9)
    stale = folder / ".values.npy.k1ll3d_0.tmp"  # killed while it rewrote values.npy with the same bytes
    stale.write_bytes(b"\x93NUMPY" + bytes(1000))
    said = []
    assert solve_twin(ds, "geodesic", 0.9, say=said.append)[2]
    assert not stale.exists() and "removed what a killed solve left" in said[0]


@pytest.mark.slow  # a live writer in a worker process: seconds (make test-all)
def test_a_live_writers_temp_file_is_never_removed(root, paused_process):
    ds = load_dataset(NAME)
    _, folder, _ = solve_twin(ds, "geodesic", 0.9)
    live = folder / ".values.npy.l1ve0000.tmp"
    live.write_bytes(b"being written")
    holder = paused_process(HOLDER, folder)
    holder.wait_for("midway")
    said = []
    assert solve_twin(ds, "geodesic", 0.9, say=said.append)[2], "a sound cache is served beside a live writer"
    assert live.read_bytes() == b"being written" and not said
    holder.kill()


@pytest.mark.slow  # waits for a writer in a worker process: seconds (make test-all)
def test_a_second_solve_waits_for_a_live_writer_and_leaves_its_temp_file(root, paused_process, capsys):
    ds = load_dataset(NAME)
    writer = paused_process(WRITER, NAME)
    writer.wait_for("midway")
    folder = folder_of(ds)
    (left,) = temps(folder)

    result, said = [], []
    second = threading.Thread(target=lambda: result.append(solve_twin(ds, "geodesic", 0.9, say=said.append)))
    second.start()
    deadline = time.monotonic() + 30
    while f"waiting for pid {writer.pid}" not in capsys.readouterr().err:
        assert time.monotonic() < deadline, "the second solve says whom it waits for"
        time.sleep(0.2)
    assert second.is_alive() and temps(folder) == [left], "the live writer's temp file is left alone"

    writer.kill()  # its lock is free now: the second solve goes on, and its temp file is a killed writer's
    second.join(timeout=120)
    assert not second.is_alive()
    sol, _, cached = result[0]
    assert not cached and temps(folder) == [] and any(left in line for line in said)
    np.testing.assert_array_equal(cache.load(folder, sol.tab).values, sol.values)
