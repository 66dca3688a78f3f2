"""Trace batches on Ray: a local Ray started on demand (one worker per core) or an existing cluster.

Each worker is a Ray actor that builds the scene once (:class:`~dtradar_data.rt.tracer.RayTracer`) and traces many
batches with the same :func:`~dtradar_data.pipeline.batches.trace_batch` as a serial build; it returns the batch's
arrays to the driver, which writes them to the build's work folder (:func:`~dtradar_data.pipeline.batches.save_batch`,
atomic). So nodes of a cluster need the package, not a shared disk; a batch is written once, whole, by one process;
and the table is assembled from the work folder exactly as after a serial build (same bytes, same version).

A worker that dies (a crash, ``kill -9``, a lost node) is restarted by Ray and its batch retried
(``max_restarts``/``max_task_retries``); if the build stops anyway, its finished batches stay in the work folder and
the next build resumes from them. Ray is optional: ``pip install 'dtradar[ray]'``. A cluster address
(``--ray-address``, ``$RAY_ADDRESS``) where nothing answers fails the build within seconds, before anything is
written (:mod:`dtradar_data.core.ray_cluster`, checked by ``build`` first), instead of Ray retrying for minutes.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.ray_cluster import RAY_INSTALL, check_ray_address, connect_ray, import_ray, wait_for_cpus
from dtradar_data.pipeline.batches import batch_path, save_batch, trace_batch

__all__ = ["RAY_INSTALL", "TraceWorker", "check_ray_address", "import_ray", "start_ray", "trace_on_ray"]

TASK_RETRIES = 3
WORKER_NOTICE_EVERY_S = 60.0


class TraceWorker:
    """One Ray actor: the scene built once, then batch after batch (pinned to one tracing thread, as serial)."""

    def __init__(self, spec, settings, per_path: bool):
        from dtradar_data.rt.tracer import RayTracer

        self.tracer = RayTracer(spec, settings)
        self.per_path = per_path

    def trace(self, b: int, points: np.ndarray, ix: np.ndarray, iy: np.ndarray):
        cells, paths = trace_batch(self.tracer, points, ix, iy, per_path=self.per_path)
        return b, cells, paths

    def pid(self) -> int:
        return os.getpid()


def start_ray(ray, address: str | None, workers: int) -> bool:
    """Connect to ``address`` (or ``$RAY_ADDRESS``), bounded: a cluster that does not answer is a
    :class:`~dtradar_data.core.errors.RayClusterError` within seconds (see
    :func:`~dtradar_data.core.ray_cluster.connect_ray`); else start a local Ray with ``workers`` CPUs (0 = all).
    True when we started or connected it."""
    return connect_ray(ray, address, num_cpus=workers or os.cpu_count() or 1)


def trace_on_ray(
    spec,
    settings,
    points: np.ndarray,
    ix: np.ndarray,
    iy: np.ndarray,
    work_dir: Path,
    todo: list[int],
    *,
    per_path: bool,
    address: str | None = None,
    workers: int = 0,
    bar=None,
) -> None:
    """Trace the batches ``todo`` of ``points`` on Ray actors, writing each to ``work_dir`` as it finishes."""
    if not todo:
        return
    ray = import_ray()
    started = start_ray(ray, address, workers)
    try:
        wait_for_cpus(ray, 1, what="a trace worker", address=address)  # else the actors would wait for ever
        cpus = int(ray.cluster_resources().get("CPU", 1))
        n_actors = max(1, min(len(todo), workers or cpus))
        actor = ray.remote(num_cpus=1, max_restarts=-1, max_task_retries=TASK_RETRIES)(TraceWorker)
        actors = [actor.remote(spec, settings, per_path) for _ in range(n_actors)]
        _wait_for_a_worker(ray, actors, spec.name, cpus)
        size = settings.batch_size
        pool = ray.util.ActorPool(actors)

        def submit(a, b):
            sl = slice(b * size, (b + 1) * size)
            return a.trace.remote(b, points[sl], ix[sl], iy[sl])

        for b, cells, paths in pool.map_unordered(submit, todo):
            save_batch(batch_path(work_dir, b), cells, paths)
            if bar is not None:
                bar.update(len(points[b * size : (b + 1) * size]))
        for a in actors:
            ray.kill(a)
    finally:
        if started:
            ray.shutdown()


def _wait_for_a_worker(ray, actors, name: str, cpus: int) -> None:
    """Wait until the first worker has started and loaded the scene, saying on stderr every
    :data:`WORKER_NOTICE_EVERY_S` how long it has waited and how busy the cluster is (a cluster whose CPUs other
    jobs hold starts none until they finish)."""
    pending = [a.pid.remote() for a in actors]
    start = time.monotonic()
    while not ray.wait(pending, num_returns=1, timeout=WORKER_NOTICE_EVERY_S)[0]:
        free = ray.available_resources().get("CPU", 0)
        print(
            f"{name}: waited {time.monotonic() - start:.0f} s for a Ray trace worker to start and load the scene "
            f"({free:g} of the cluster's {cpus} CPUs free; Ctrl-C is safe, finished batches are kept)",
            file=sys.stderr,
            flush=True,
        )
