"""Trace batches on Ray: a local Ray started on demand (one worker per core) or an existing cluster.

Each worker is a Ray actor that builds a scene's tracer when it first gets one of its batches
(:class:`~dtradar_data.rt.tracer.RayTracer`) and keeps it for the scene's other batches; it traces with the same
:func:`~dtradar_data.pipeline.batches.trace_batch` as a serial build and returns the batch's arrays to the driver,
which writes them to the build's work folder (:func:`~dtradar_data.pipeline.batches.save_batch`, atomic). So nodes of
a cluster need the package, not a shared disk; a batch is written once, whole, by one process; and the table is
assembled from the work folder exactly as after a serial build (same bytes, same version).

**Warm workers.** A build of several scenes (a city's quadrants and variants, a moving twin's snapshots) runs in one
:class:`RaySession`: Ray is started once and its workers live for the whole build, so a worker imports the ray tracer
and compiles its kernels once, not once per scene (measured in docs/scaling.md). A call of :func:`trace_on_ray`
outside a session opens one for itself.

A worker that dies (a crash, ``kill -9``, a lost node) is restarted by Ray and its batch retried
(``max_restarts``/``max_task_retries``; every call carries its scene, so a fresh worker needs nothing else); if the
build stops anyway, its finished batches stay in the work folder and the next build resumes from them. Ray is
optional: ``pip install 'dtradar[ray]'``. A cluster address (``--ray-address``, ``$RAY_ADDRESS``) where nothing
answers fails the build within seconds, before anything is written (:mod:`dtradar_data.core.ray_cluster`, checked by
``build`` first), instead of Ray retrying for minutes.
"""

from __future__ import annotations

import contextvars
import os
import sys
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.ray_cluster import RAY_INSTALL, check_ray_address, connect_ray, import_ray, wait_for_cpus
from dtradar_data.pipeline.batches import batch_path, save_batch, trace_batch

__all__ = ["RAY_INSTALL", "RaySession", "TraceWorker", "check_ray_address", "import_ray", "start_ray", "trace_on_ray"]

TASK_RETRIES = 3
WORKER_NOTICE_EVERY_S = 60.0
_SESSION: contextvars.ContextVar[RaySession | None] = contextvars.ContextVar("dtradar_ray_session", default=None)


class TraceWorker:
    """One Ray actor: batch after batch, the tracer of the batch's scene built once (pinned to one tracing thread, as
    serial) and kept until a batch of another scene comes."""

    def __init__(self):
        self.key = None
        self.tracer = None

    def trace(self, key: str, scene, b: int, points: np.ndarray, ix: np.ndarray, iy: np.ndarray):
        """Trace batch ``b`` of the scene ``scene = (spec, settings, per_path)``, named ``key`` within the build."""
        spec, settings, per_path = scene
        if key != self.key:
            from dtradar_data.rt.tracer import RayTracer

            if self.tracer is not None:
                self.tracer.close()
            self.tracer, self.key = RayTracer(spec, settings), key
        cells, paths = trace_batch(self.tracer, points, ix, iy, per_path=per_path)
        return b, cells, paths

    def pid(self) -> int:
        return os.getpid()


def start_ray(ray, address: str | None, workers: int) -> bool:
    """Connect to ``address`` (or ``$RAY_ADDRESS``), bounded: a cluster that does not answer is a
    :class:`~dtradar_data.core.errors.RayClusterError` within seconds (see
    :func:`~dtradar_data.core.ray_cluster.connect_ray`); else start a local Ray with ``workers`` CPUs (0 = all).
    True when we started or connected it."""
    return connect_ray(ray, address, num_cpus=workers or os.cpu_count() or 1)


class RaySession:
    """Ray and its trace workers for one build (module docstring): ``with RaySession(address, workers): ...``; every
    :func:`trace_on_ray` inside it uses the same warm workers. Ray is started (or connected) at the first batch, so a
    build that only reuses stored versions never starts it; it is shut down on leaving if the session started it (a
    Ray the caller initialised, or a cluster's, stays up; the workers are released)."""

    def __init__(self, address: str | None = None, workers: int = 0):
        self.address, self.workers = address, workers
        self.ray = None
        self.actors: list = []
        self._started = False
        self._token = None
        self._scenes = 0

    def __enter__(self) -> RaySession:
        self._token = _SESSION.set(self)
        return self

    def __exit__(self, *exc) -> None:
        _SESSION.reset(self._token)
        try:
            for a in self.actors:
                self.ray.kill(a)
        finally:
            self.actors = []
            if self._started:
                self.ray.shutdown()
                self._started = False

    def pool(self, name: str, need: int):
        """Up to ``need`` of the session's workers (at most one per CPU of the cluster, or ``workers``), started as
        needed and kept: waits until the cluster can run one (:func:`~dtradar_data.core.ray_cluster.wait_for_cpus`)
        and the first has started."""
        if self.ray is None:
            self.ray = import_ray()
            self._started = start_ray(self.ray, self.address, self.workers)
        ray = self.ray
        first = not self.actors
        if first:
            wait_for_cpus(ray, 1, what="a trace worker", address=self.address)  # else the actors would wait for ever
        cpus = int(ray.cluster_resources().get("CPU", 1))
        want = max(1, min(need, self.workers or cpus))
        if len(self.actors) < want:
            actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=TASK_RETRIES)(TraceWorker)
            self.actors += [actor.remote() for _ in range(want - len(self.actors))]
        if first:
            _wait_for_a_worker(ray, self.actors, name, cpus)
        return self.actors[:want]

    def scene_key(self) -> str:
        self._scenes += 1
        return f"scene-{self._scenes}"


def trace_on_ray(
    spec,
    settings,
    points: np.ndarray,
    ix: np.ndarray,
    iy: np.ndarray,
    work_dir: Path,
    todo: list[int],
    *,
    size: int | None = None,
    per_path: bool,
    address: str | None = None,
    workers: int = 0,
    bar=None,
) -> None:
    """Trace the batches ``todo`` (of ``size`` cells; default ``settings.batch_size``) of ``points`` on the Ray
    workers of the current :class:`RaySession` (or of one opened for this call), writing each to ``work_dir`` as it
    finishes."""
    if not todo:
        return
    session = _SESSION.get()
    if session is None:
        with RaySession(address, workers) as session:
            return _trace(session, spec, settings, points, ix, iy, work_dir, todo, size, per_path, bar)
    return _trace(session, spec, settings, points, ix, iy, work_dir, todo, size, per_path, bar)


def _trace(session, spec, settings, points, ix, iy, work_dir, todo, size, per_path, bar) -> None:
    actors = session.pool(getattr(spec, "name", "ray tracing"), len(todo))
    ray = session.ray
    key = session.scene_key()
    scene = ray.put((spec, settings, per_path))  # once in the object store, not once per batch
    size = size or settings.batch_size
    pool = ray.util.ActorPool(actors)

    def submit(a, b):
        sl = slice(b * size, (b + 1) * size)
        return a.trace.remote(key, scene, b, points[sl], ix[sl], iy[sl])

    for b, cells, paths in pool.map_unordered(submit, todo):
        save_batch(batch_path(work_dir, b), cells, paths)
        if bar is not None:
            bar.update(len(points[b * size : (b + 1) * size]))


def _wait_for_a_worker(ray, actors, name: str, cpus: int) -> None:
    """Wait until the first worker has started, saying on stderr every :data:`WORKER_NOTICE_EVERY_S` how long it has
    waited and how busy the cluster is (a cluster whose CPUs other jobs hold starts none until they finish)."""
    pending = [a.pid.remote() for a in actors]
    start = time.monotonic()
    while not ray.wait(pending, num_returns=1, timeout=WORKER_NOTICE_EVERY_S)[0]:
        free = ray.available_resources().get("CPU", 0)
        print(
            f"{name}: waited {time.monotonic() - start:.0f} s for a Ray trace worker to start "
            f"({free:g} of the cluster's {cpus} CPUs free; Ctrl-C is safe, finished batches are kept)",
            file=sys.stderr,
            flush=True,
        )
