"""How the offline benchmark's trainings run: one :class:`BenchJob` per (dataset, algorithm, seed), trained,
evaluated and (with FQE) off-policy evaluated by :func:`run_job`, in this process or in spawned worker processes with
one torch thread each (:func:`run_jobs`), as many as the cores measurably work in parallel (:func:`auto_workers`),
or as Ray tasks of one CPU each (:func:`run_jobs_on_ray`, ``--executor ray``, the executor of sweeps: a local Ray on
this machine's cores or a cluster at an address). A job is seeded and trains on one torch thread, so its row is the
same wherever it runs. :mod:`dtradar_rl.experiments.offline_plan` builds the jobs and
:mod:`dtradar_rl.experiments.offline_bench` gathers their rows.

A finished job's row is kept in its run folder (:func:`save_row`, written whole), with everything the row depends
on (:func:`job_key`): a benchmark that was interrupted and runs again reuses those rows (:func:`finished_row`) and
trains only the rest. A job starts by removing what an unfinished earlier attempt left in its folder (a worker
killed mid-write, an interrupted benchmark), so a run folder holds one attempt's files, never a mix. A job whose
worker dies (``kill -9``, the OOM killer) is retried on Ray; a job whose worker died every time fails the benchmark
with :class:`TrainingLostError`, naming it, with the unfinished jobs' folders removed."""

from __future__ import annotations

import json
import math
import multiprocessing
import multiprocessing.connection
import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any

import torch

from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import write_atomic
from dtradar_data.store import library_versions
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


class TrainingLostError(DtradarError, RuntimeError):
    """A benchmark training whose worker process died every time it ran it (killed, out of memory, its node lost)."""


#: The finished row of a job in its run folder, with what it depends on.
ROW_FILE = "bench_row.json"
#: Libraries a row depends on beside the job's settings: another version may train other weights.
ROW_LIBRARIES = ("dtradar", "d3rlpy", "torch", "numpy")


def job_key(job: BenchJob) -> dict[str, Any]:
    """Everything a job's row depends on: its settings (the training's config included), the logged dataset's
    version and the libraries' versions, as JSON stores it."""
    key = {
        "behaviour": job.behaviour,
        "algorithm": job.algorithm,
        "seed": job.seed,
        "logged": job.logged,
        "fqe_steps": job.fqe_steps,
        "fqe_gamma": job.fqe_gamma,
        "config": job.config.to_dict(),
        "libraries": library_versions(ROW_LIBRARIES),
    }
    return json.loads(json.dumps(key))


def finished_row(job: BenchJob) -> dict[str, Any] | None:
    """The row an earlier run of ``job`` saved in its run folder, when it ran with the same settings, data and
    libraries; else None (never run, unfinished, or run otherwise: it trains again)."""
    try:
        saved = json.loads((job.config.out_dir / ROW_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(saved, dict) or saved.get("job") != job_key(job) or not isinstance(saved.get("row"), dict):
        return None
    return saved["row"]


def save_row(job: BenchJob, row: dict[str, Any]) -> None:
    """Keep ``row`` in the job's run folder (whole or not at all), for a benchmark that runs again to reuse."""
    write_atomic(job.config.out_dir / ROW_FILE, json.dumps({"job": job_key(job), "row": row}, indent=2) + "\n")


def remove_unfinished(jobs: list[BenchJob]) -> None:
    """Remove the run folders of ``jobs`` that hold no finished row: what a dead or stopped attempt left half done."""
    for job in jobs:
        if not (job.config.out_dir / ROW_FILE).is_file():
            shutil.rmtree(job.config.out_dir, ignore_errors=True)


def describe(job: BenchJob) -> str:
    return f"{job.algorithm} on {job.behaviour} (seed {job.seed}, {job.logged}; {job.config.out_dir})"


_OPENED: dict[str, Any] = {}  # twins and logged datasets already opened in this process


def _opened(key: str, load: Callable[[], Any]) -> Any:
    if key not in _OPENED:
        _OPENED[key] = load()
    return _OPENED[key]


def run_job(job: BenchJob) -> dict[str, Any]:
    """Train, evaluate and (``job.fqe_steps``) off-policy evaluate one agent; its row of ``bench.json``."""
    cfg = job.config
    # The benchmark holds its --out: this folder is this job's alone, and what is there is an earlier attempt's
    # (a killed worker's, an interrupted run's, a row not reused), replaced whole rather than mixed with this one.
    shutil.rmtree(cfg.out_dir, ignore_errors=True)
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
        # what --precision and --batch-size resolved to for this algorithm on this CPU (auto: bf16 where it runs)
        "precision": cfg.update_precision,
        "batch_size": cfg.update_batch_size,
        **{
            v: _row_metrics(r.rows, f"{scene}/{v}")
            for v in cfg.eval_variants
            if any(x["dataset"] == f"{scene}/{v}" for x in r.rows)
        },
    }
    if job.fqe_steps:
        t1 = time.perf_counter()
        settings = logged.meta.get("settings") or {}
        # FQE replays the log as the agent observed it (with --senses memory, the memory window appended)
        run["fqe"] = fqe_estimate(r.policy, r.data, n_steps=job.fqe_steps, seed=job.seed, gamma=job.fqe_gamma)
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
    # A benchmark killed by a signal runs no clean-up, and its workers went on training the jobs already queued to
    # them (seen: two, ten minutes after a SIGTERM); each worker leaves when its parent does.
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with_parent, args=(parent.sentinel,), daemon=True).start()


def _exit_with_parent(sentinel: int) -> None:
    multiprocessing.connection.wait([sentinel])
    os._exit(1)


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
    or in this process when ``workers`` is 1 or there is a single job. When one fails (or the benchmark is
    interrupted), what the unfinished jobs left in their run folders is removed; a worker process that died is a
    :class:`TrainingLostError`."""
    rows: list[dict[str, Any]] = []
    if workers <= 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            try:
                rows.append(run_job(job))
            except BaseException:
                remove_unfinished(jobs[i : i + 1])
                raise
            done(rows[-1])
        return rows
    # spawn, not fork: a forked child inherits torch's thread pool state and can deadlock in it
    ctx = get_context("spawn")
    of: dict[Any, BenchJob] = {}
    try:
        with ProcessPoolExecutor(max_workers=min(workers, len(jobs)), mp_context=ctx, initializer=_init_worker) as pool:
            of = {pool.submit(run_job, job): job for job in jobs}
            for fut in as_completed(of):
                rows.append(fut.result())
                done(rows[-1])
    except BaseException as e:
        ok = [fut for fut in of if fut.done() and not fut.cancelled() and fut.exception() is None]
        remove_unfinished([job for fut, job in of.items() if fut not in ok])
        if isinstance(e, BrokenProcessPool):
            raise TrainingLostError(
                f"a training process died while the benchmark ran ({e}: killed, or out of memory); the benchmark "
                "stopped, its finished runs are kept",
                hint="run the benchmark again: it reuses the finished runs and trains the rest; if a process dies "
                "every time, run fewer side by side (--workers 1)",
            ) from e
        raise
    return rows


def check_ray(address: str | None) -> None:
    """For ``--executor ray``, before anything is logged or trained: Ray is installed and something answers at the
    cluster ``address`` (or ``$RAY_ADDRESS``; none: a local Ray, nothing to reach), else the typed error naming the
    address and its fix. Found only when the trainings start, every dataset would be logged and stored first (and the
    online agent trained); :func:`run_jobs_on_ray` connects, bounded, again then."""
    from dtradar_data.core.ray_cluster import check_ray_address
    from dtradar_rl.experiments.sweep import _import_ray

    _import_ray(instead="local")  # offline-bench has no serial executor
    check_ray_address(address)


def run_jobs_on_ray(
    jobs: list[BenchJob], address: str | None = None, done: Callable[[dict[str, Any]], None] = lambda run: None
) -> list[dict[str, Any]]:
    """Every job's row as a Ray task of one CPU (in the order they finish; ``done`` is called with each): a local
    Ray on this machine's cores, or the cluster at ``address`` (whose nodes must hold the same data root: a job
    opens its twin and its logged dataset there by name). A task whose worker dies is retried twice
    (:data:`RAY_RETRIES`); one that fails for good stops the others, removes what the unfinished ones left in their
    run folders and raises (:func:`_lost`)."""
    from dtradar_data.core.ray_cluster import connect_ray, wait_for_cpus
    from dtradar_rl.experiments.sweep import _import_ray

    ray = _import_ray(instead="local")  # offline-bench has no serial executor
    started = connect_ray(ray, address)  # bounded: a dead address fails in seconds, not minutes
    rows: list[dict[str, Any]] = []
    try:
        wait_for_cpus(ray, 1, what="one training (1 CPU)", address=address)
        task = ray.remote(num_cpus=1, max_retries=RAY_RETRIES)(_ray_job)
        of = {task.remote(job): job for job in jobs}
        pending = list(of)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            try:
                rows.append(ray.get(ready[0]))
            except ray.exceptions.RayError as e:
                _stop(ray, pending)
                # their workers are gone: what they left half written goes too
                remove_unfinished([of[ref] for ref in [ready[0], *pending]])
                raise _lost(ray, e, of[ready[0]]) from e
            done(rows[-1])
    finally:
        if started:
            ray.shutdown()
    return rows


#: How often Ray runs a training again whose worker died (not one that raised: that fails the same way again).
RAY_RETRIES = 2


def _stop(ray, pending: list) -> None:
    """Cancel the trainings still queued or running (their workers killed) and wait, for a while, until they are."""
    for ref in pending:
        ray.cancel(ref, force=True)
    if pending:
        ray.wait(pending, num_returns=len(pending), timeout=30.0)


def _lost(ray, e: BaseException, job: BenchJob) -> BaseException:
    """What to raise for a job that failed on Ray: its own typed error as it is (a setting, the data), a dead
    worker as :class:`TrainingLostError`, anything else (a bug) unchanged."""
    cause = getattr(e, "cause", None)
    if isinstance(e, ray.exceptions.RayTaskError):
        return cause if isinstance(cause, DtradarError) else e
    return TrainingLostError(
        f"the training {describe(job)} lost its Ray worker {RAY_RETRIES + 1} times ({type(e).__name__}: the "
        "worker process died: killed, out of memory, or its node gone); the benchmark stopped, its finished runs "
        "are kept",
        hint="run the benchmark again: it reuses the finished runs and trains the rest; if the worker dies every "
        "time, give the Ray workers more memory, or run it with --executor local",
    )


def _ray_job(job: BenchJob) -> dict[str, Any]:
    torch.set_num_threads(1)  # as a worker process does: the same arithmetic, so the same row
    return run_job(job)


__all__ = ["BenchJob", "auto_workers", "check_ray", "parallel_gain", "run_job", "run_jobs", "run_jobs_on_ray"]
