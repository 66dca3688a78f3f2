"""Helper processes: the cells of one re-trace traced in several processes at once, joined in their order.

Why: every trace is pinned to one Dr.Jit thread (``RTSettings.deterministic``: its multi-threaded path collection
changes the weak paths from run to run), so a build tracing in one process leaves every other core idle, and a moving
twin's differential snapshot costs what its trace costs (cProfile of a cubicle build: about 95 % of a snapshot's
time is Dr.Jit kernels; loading the scene, choosing the cells and writing the tables are the rest). With
batch-independent tracing a cell's rows are the same bytes whatever other cells share its PathSolver call
(:mod:`dtradar_data.rt.tracer`, "Batch independence"), so the cells are cut into contiguous parts in row-major order
(:func:`parts`), each traced by its own process at the same time, and joined in that order: the same tables, byte for
byte, in about ``1/P`` of the time. With Sionna's own solver a row depends on its batch: nothing is split there.

A helper is a fresh interpreter running :func:`serve` (``python -c "...; serve(FD)"``), not a
:mod:`multiprocessing` child: those re-run the caller's main script, which a user's script without a ``__main__``
guard would turn into a second build. It talks over one socket (pickled requests and replies), loads the tracer
of snapshot 0's scene as soon as it starts (so its start overlaps snapshot 0's full trace), builds the tracer of a
new scene when it gets that scene's first part and keeps it until another comes, as a Ray worker does
(:mod:`.executors`). A helper that dies leaves its parts to this process (a notice says so); an error it raises
while tracing is raised here. How many: :func:`helper_count`, one per core beyond this process's within memory.
"""

from __future__ import annotations

import multiprocessing.connection
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from dtradar_data.core.machine import available_memory
from dtradar_data.pipeline.batches import trace_batch
from dtradar_data.pipeline.resources import estimate_memory

__all__ = ["MIN_CELLS_PER_PART", "TraceHelpers", "helper_count", "parts"]

#: No part is smaller than this: every PathSolver call shoots all ``samples_per_src`` rays again, so below it the
#: shooting that each part repeats outweighs the cells it takes off this process (a grid of fewer free cells than
#: twice this is traced in one process: the tests' small corridors start no helper).
MIN_CELLS_PER_PART = 64
STOP_WAIT_S = 30.0  # how long a helper may take to exit once told to


def helper_count(free_cells: int, settings, *, cores: int | None = None, memory: int | None = None) -> int:
    """Helper processes for a build of ``free_cells`` free cells per snapshot: one per core beyond this process's,
    as many as the memory holds beside this process (:func:`estimate_memory` each), at most one per
    :data:`MIN_CELLS_PER_PART` cells beyond the first part; none with Sionna's own solver."""
    if not settings.batch_independent:
        return 0
    if cores is None:
        cores = _usable_cores()
    if memory is None:
        memory = available_memory()
    by_memory = cores - 1 if memory is None else memory // estimate_memory(settings) - 1
    return max(0, min(cores - 1, by_memory, free_cells // MIN_CELLS_PER_PART - 1))


def _usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - platforms without affinity
        return os.cpu_count() or 1


def parts(n: int, settings, processes: int) -> list[slice]:
    """``n`` cells (row-major) as contiguous parts, one trace call each: as few as ``settings.batch_size`` allows,
    but at least one per process where each part keeps :data:`MIN_CELLS_PER_PART` cells; their sizes differ by one
    at most."""
    if n == 0:
        return []
    calls = max(-(-n // settings.batch_size), min(processes, n // MIN_CELLS_PER_PART))
    bounds = [n * i // calls for i in range(calls + 1)]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


class TraceHelpers:
    """``count`` helper processes tracing parts of a re-trace beside this process (none: everything here), each
    started with the tracer of ``spec`` loaded. Use as a context manager, or :meth:`close` it: the helpers end with
    it."""

    def __init__(self, count: int, spec=None, settings=None):
        self._helpers: list[_Helper] = []
        try:
            for _ in range(count):
                self._helpers.append(_Helper())
                if spec is not None:
                    self._helpers[-1].send(("start", _key(spec, settings), spec, settings))
        except BaseException:
            self.close()
            raise

    @property
    def count(self) -> int:
        """Helpers still alive."""
        return len(self._helpers)

    def __enter__(self) -> TraceHelpers:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        while self._helpers:
            self._helpers.pop().stop()

    def splits(self, n: int, settings) -> bool:
        """Whether :meth:`trace` shares ``n`` cells with the helpers (else they are traced here as before)."""
        return self.count > 0 and settings.batch_independent and len(parts(n, settings, self.count + 1)) > 1

    def trace(self, tracer, spec, settings, points: np.ndarray, ix: np.ndarray, iy: np.ndarray, *, per_path: bool):
        """``[(slice, (cells, paths))]`` of every part of the cells ``points`` (of ``ix``, ``iy``) in ``spec``, in
        row-major order, each :func:`~dtradar_data.pipeline.batches.trace_batch`'s result: part ``i`` traced by
        helper ``i % P - 1`` (``P`` processes), or by this process's ``tracer`` where that is -1 or the helper died."""
        processes = self.count + 1
        slices = parts(len(points), settings, processes)
        mine = {h: [i for i in range(len(slices)) if i % processes == h + 1] for h in range(self.count)}
        key = _key(spec, settings)
        sent = {}
        for h, helper in enumerate(self._helpers):
            jobs = [(points[slices[i]], ix[slices[i]], iy[slices[i]]) for i in mine[h]]
            sent[h] = helper.send(("trace", key, spec, settings, jobs, per_path))

        def here(i: int):
            sl = slices[i]
            return trace_batch(tracer, points[sl], ix[sl], iy[sl], per_path=per_path)

        done = {i: here(i) for i in range(0, len(slices), processes)}
        lost = []
        for h, helper in enumerate(self._helpers):
            results = helper.receive() if sent[h] else None
            if results is None:  # the helper died: its parts are traced here, and it gets no more
                lost.append(helper)
                done.update((i, here(i)) for i in mine[h])
            else:
                done.update(zip(mine[h], results))
        for helper in lost:
            self._helpers.remove(helper)
            helper.stop()
        return [(sl, done[i]) for i, sl in enumerate(slices)]


def _key(spec, settings):
    return spec.digest(), settings


class _Helper:
    """One helper process and this end of its socket."""

    def __init__(self):
        ours, theirs = multiprocessing.connection.Pipe()
        package_root = str(Path(__file__).resolve().parents[2])  # found by the helper even where not installed
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")]))}
        fd = theirs.fileno()
        self.proc = subprocess.Popen(
            [sys.executable, "-c", f"from dtradar_data.pipeline.trace_helpers import serve; serve({fd})"],
            pass_fds=[fd],
            env=env,
        )
        theirs.close()
        self.conn = ours

    def send(self, message) -> bool:
        """Send a request; False when the helper is gone."""
        try:
            self.conn.send(message)
            return True
        except (OSError, EOFError):
            _notice(self.proc)
            return False

    def receive(self):
        """The reply to a trace request: its results, None when the helper died; an error it raised, raised."""
        try:
            status, value = self.conn.recv()
        except (OSError, EOFError):
            _notice(self.proc)
            return None
        if status == "error":
            raise value
        return value

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, EOFError):
            pass
        self.conn.close()
        try:
            self.proc.wait(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _notice(proc) -> None:
    code = proc.poll()
    how = f" (exit code {code})" if code is not None else ""
    print(
        f"a trace helper process (pid {proc.pid}) stopped{how}; this process traces its cells from now on",
        file=sys.stderr,
    )


# ------------------------------------------------------------------------------------------- in a helper process
def serve(fd: int) -> None:
    """A helper's loop on the socket ``fd``: ``("start", key, spec, settings)`` loads a scene's tracer;
    ``("trace", key, spec, settings, jobs, per_path)`` traces each job ``(points, ix, iy)`` in that scene and replies
    ``("ok", [(cells, paths), ...])`` or ``("error", exception)``; ``None`` or a closed socket ends it."""
    conn = multiprocessing.connection.Connection(fd)
    try:
        _serve(conn)
    except KeyboardInterrupt:  # Ctrl-C reaches the helpers too: the build reports it, not each of them
        pass


def _serve(conn) -> None:
    tracer, current = None, None
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            break
        if message is None:
            break
        kind, key, spec, settings = message[:4]
        try:
            if key != current:
                from dtradar_data.rt.tracer import RayTracer

                if tracer is not None:
                    tracer.close()
                tracer, current = None, None
                tracer, current = RayTracer(spec, settings), key
            if kind == "trace":
                jobs, per_path = message[4:]
                conn.send(("ok", [trace_batch(tracer, p, x, y, per_path=per_path) for p, x, y in jobs]))
        except Exception as e:
            if kind == "trace":  # a failed start is tried again, and reported, at the first trace request
                conn.send(("error", e))
    if tracer is not None:
        tracer.close()
