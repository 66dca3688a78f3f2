"""How the offline benchmark's trainings run: one :class:`BenchJob` per (dataset, algorithm, seed), trained,
evaluated and (with FQE) off-policy evaluated by :func:`run_job`, in this process or in spawned worker processes with
one torch thread each (:func:`run_jobs`), as many as the cores measurably work in parallel (:func:`auto_workers`),
or as Ray tasks of one CPU each (:func:`run_jobs_on_ray`, ``--executor ray``, the executor of sweeps: a local Ray on
this machine's cores or a cluster at an address). A job is seeded and trains on one torch thread, so its row is the
same wherever it runs. :mod:`dtradar_rl.experiments.offline_bench` builds the jobs and gathers their rows."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any

import torch

from dtradar_rl.evaluation.evaluate import METRICS
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.formats import as_logged
from dtradar_rl.offline.ope import FQE_GAMMA, episode_starts, fqe_estimate, true_value
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.twins import load_dataset


def _row_metrics(rows: list[dict[str, Any]], variant_name: str) -> dict[str, float]:
    row = next(r for r in rows if r["dataset"] == variant_name and not r.get("shield"))
    return {m: float(row[m]) for m in METRICS}


@dataclass(frozen=True)
class BenchJob:
    """One training of the benchmark: an algorithm and seed on one logged dataset (``name@version``), with its
    evaluation, and FQE beside the true value when ``fqe_steps`` > 0."""

    behaviour: str
    algorithm: str
    seed: int
    logged: str
    config: OfflineConfig
    fqe_steps: int = 0
    fqe_gamma: float = FQE_GAMMA


_OPENED: dict[str, Any] = {}  # twins and logged datasets already opened in this process


def _opened(key: str, load: Callable[[], Any]) -> Any:
    if key not in _OPENED:
        _OPENED[key] = load()
    return _OPENED[key]


def run_job(job: BenchJob) -> dict[str, Any]:
    """Train, evaluate and (``job.fqe_steps``) off-policy evaluate one agent; its row of ``bench.json``."""
    cfg = job.config
    torch.set_num_threads(cfg.threads or 1)
    scene = cfg.scene
    logged = _opened(job.logged, lambda: as_logged(job.logged))
    blueprint = _opened(f"{scene}/blueprint", lambda: load_dataset(f"{scene}/blueprint"))
    t0 = time.perf_counter()
    r = train_offline(cfg, dataset=logged)
    run: dict[str, Any] = {
        "behaviour": job.behaviour,
        "algorithm": job.algorithm,
        "seed": job.seed,
        "train_s": r.train_s,
        "wall_s": r.wall_s,
        "final_losses": r.losses[-1] if r.losses else {},
        "pid": os.getpid(),
        **{
            v: _row_metrics(r.rows, f"{scene}/{v}")
            for v in cfg.eval_variants
            if any(x["dataset"] == f"{scene}/{v}" for x in r.rows)
        },
    }
    if job.fqe_steps:
        t1 = time.perf_counter()
        settings = logged.meta.get("settings") or {}
        run["fqe"] = fqe_estimate(r.policy, logged, n_steps=job.fqe_steps, seed=job.seed, gamma=job.fqe_gamma)
        run["fqe_s"] = time.perf_counter() - t1
        starts = _opened(f"starts:{job.logged}", lambda: episode_starts(logged))
        run["true_value"] = true_value(
            r.policy,
            blueprint,
            starts,
            gamma=job.fqe_gamma,
            reward=settings.get("reward", cfg.reward),
            max_steps=settings.get("max_steps") or None,
            device=cfg.device,
        )
    run["job_s"] = time.perf_counter() - t0
    return run


def _init_worker() -> None:
    torch.set_num_threads(1)


#: a bare Python loop that counts for a while and prints the count (a process's share of the CPU)
_SPIN = "import time\nt = time.perf_counter()\nn = 0\nwhile time.perf_counter() - t < {s}:\n    n += 1\nprint(n)"


def parallel_gain(k: int, seconds: float = 0.5) -> float:
    """How much more work ``k`` processes side by side do than one, right now: a counting loop run alone, then ``k``
    at once (fresh interpreters, ``seconds`` each). About ``k`` on ``k`` idle cores; on this 2-core VM, 0.8-1.2 for
    two while three other jobs kept it busy, 1.6-2.1 beside one."""
    code = _SPIN.format(s=seconds)

    def work(m: int) -> int:
        procs = [subprocess.Popen([sys.executable, "-S", "-c", code], stdout=subprocess.PIPE) for _ in range(m)]
        return sum(int(p.communicate()[0] or 0) for p in procs)

    return work(k) / max(1, work(1))


def auto_workers(n_jobs: int) -> tuple[int, float | None]:
    """Training processes for ``n_jobs`` trainings, and the :func:`parallel_gain` measured to choose: as many as the
    cores do proportionally more work with (a gain of 1.3 or more for a second process), at most one per core and
    per job. Measured with ``bench/bench_offline_speed.py --sections parallel`` on this 2-core VM: beside three busy
    jobs two worker processes halved every training's speed (1.0x the updates in all; 0.47x with their ~10 s
    start-up, importing d3rlpy and opening the data, on short jobs); beside one busy job each kept ~80 % of its
    speed (1.56x the updates in all; 1.18x with the start-up on four jobs of 3000 updates). Choosing two when one
    would do costs only the start-up; choosing one when two would do costs a third of the time."""
    k = min(n_jobs, os.cpu_count() or 1)
    if k < 2:
        return 1, None
    gain = parallel_gain(k)
    return max(1, min(k, math.floor(gain + 0.7))), gain


def run_jobs(
    jobs: list[BenchJob], workers: int, done: Callable[[dict[str, Any]], None] = lambda run: None
) -> list[dict[str, Any]]:
    """Every job's row (in the order they finish; ``done`` is called with each): ``workers`` spawned processes at once,
    or in this process when ``workers`` is 1 or there is a single job."""
    if workers <= 1 or len(jobs) <= 1:
        rows = []
        for job in jobs:
            rows.append(run_job(job))
            done(rows[-1])
        return rows
    rows = []
    # spawn, not fork: a forked child inherits torch's thread pool state and can deadlock in it
    ctx = get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=ctx, initializer=_init_worker) as pool:
        for fut in as_completed([pool.submit(run_job, job) for job in jobs]):
            rows.append(fut.result())
            done(rows[-1])
    return rows


def run_jobs_on_ray(
    jobs: list[BenchJob], address: str | None = None, done: Callable[[dict[str, Any]], None] = lambda run: None
) -> list[dict[str, Any]]:
    """Every job's row as a Ray task of one CPU (in the order they finish; ``done`` is called with each): a local
    Ray on this machine's cores, or the cluster at ``address`` (whose nodes must hold the same data root: a job
    opens its twin and its logged dataset there by name). A task whose worker dies is retried twice."""
    from dtradar_data.core.ray_cluster import connect_ray, wait_for_cpus
    from dtradar_rl.experiments.sweep import _import_ray

    ray = _import_ray()
    started = connect_ray(ray, address)  # bounded: a dead address fails in seconds, not minutes
    rows: list[dict[str, Any]] = []
    try:
        wait_for_cpus(ray, 1, what="one training (1 CPU)", address=address)
        task = ray.remote(num_cpus=1, max_retries=2)(_ray_job)
        pending = [task.remote(job) for job in jobs]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            rows.append(ray.get(ready[0]))
            done(rows[-1])
    finally:
        if started:
            ray.shutdown()
    return rows


def _ray_job(job: BenchJob) -> dict[str, Any]:
    torch.set_num_threads(1)  # as a worker process does: the same arithmetic, so the same row
    return run_job(job)


__all__ = ["BenchJob", "auto_workers", "parallel_gain", "run_job", "run_jobs", "run_jobs_on_ray"]
