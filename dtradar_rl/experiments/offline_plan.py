"""The offline benchmark's trainings planned before any of them runs: one :class:`BenchJob` per (dataset, algorithm,
seed) with its :class:`~dtradar_rl.offline.config.OfflineConfig` (:func:`bench_jobs`), the rows an interrupted
benchmark already finished (:func:`reused_rows`), and where the rest run (:func:`training_layout`).
:mod:`dtradar_rl.experiments.offline_bench` runs the plan; :mod:`dtradar_rl.experiments.offline_jobs` each job."""

from __future__ import annotations

from typing import Any

from dtradar_rl.experiments.offline_bench_config import OfflineBenchConfig
from dtradar_rl.experiments.offline_jobs import BenchJob, auto_workers, finished_row
from dtradar_rl.offline.config import BF16_ALGORITHMS, OfflineConfig


def bench_jobs(cfg: OfflineBenchConfig, ids: dict[str, str]) -> list[BenchJob]:
    """Every (dataset, algorithm, seed) training of ``cfg``, datasets outermost and seeds innermost (the order of
    ``bench.json``'s runs); none with ``--no-deep``."""
    return [
        BenchJob(
            behaviour=beh,
            algorithm=algo,
            seed=seed,
            logged=ids[beh],
            config=OfflineConfig(
                scene=cfg.scene,
                algorithm=algo,
                seed=seed,
                n_steps=cfg.n_steps,
                batch_size=cfg.batch_size,
                precision="fp32" if cfg.precision == "bf16" and algo not in BF16_ALGORITHMS else cfg.precision,
                relabel=cfg.relabel,
                senses=cfg.senses,
                sensing=cfg.sensing,
                sensing_noise=cfg.sensing_noise,
                pairs=cfg.pairs,
                eval_variants=tuple(cfg.variants),
                shield=False,
                latency=False,  # not reported here; ~0.5 s per twin and run
                device=cfg.device,
                num_envs=cfg.num_envs,
                threads=1,
                verbose=False,
                out=str(cfg.out_dir / "runs" / beh / algo / f"seed{seed}"),
            ),
            fqe_steps=cfg.fqe_steps if cfg.fqe else 0,
            fqe_gamma=cfg.fqe_gamma,
        )
        for beh in cfg.behaviours
        for algo in (cfg.algorithms if cfg.deep else ())
        for seed in cfg.seeds
    ]


def reused_rows(cfg: OfflineBenchConfig, jobs: list[BenchJob], say) -> tuple[dict[int, dict[str, Any]], list[BenchJob]]:
    """The rows of ``jobs`` already finished in their run folders (by index; none with ``--no-reuse``) and the jobs
    left to train."""
    # an interrupted benchmark's finished runs (same settings, data, libraries) are not trained again
    reused = {i: row for i, job in enumerate(jobs) if cfg.reuse and (row := finished_row(job)) is not None}
    todo = [job for i, job in enumerate(jobs) if i not in reused]
    if reused:
        runs = cfg.out_dir / "runs"
        say(f"reusing {len(reused)} of {len(jobs)} runs finished in {runs} (--no-reuse trains them again)")
    return reused, todo


def training_layout(cfg: OfflineBenchConfig, todo: list[BenchJob], n_reused: int, say) -> tuple[int, dict[str, Any]]:
    """The worker processes the ``todo`` trainings run in (0 on Ray) and the layout ``bench.json`` records."""
    if cfg.executor == "ray":
        workers, gain = 0, None
        layout = {"jobs": len(todo), "executor": "ray", "ray_address": cfg.ray_address, "torch_threads": 1}
        say(f"{len(todo)} trainings of {cfg.n_steps} updates as Ray tasks of 1 CPU, 1 torch thread each")
    else:
        workers, gain = (cfg.workers, None) if cfg.workers else auto_workers(len(todo))
        workers = min(workers, max(1, len(todo)))
        layout = {"jobs": len(todo), "workers": workers, "torch_threads": 1, "parallel_gain": gain}
        say(f"{len(todo)} trainings of {cfg.n_steps} updates in {workers} process(es), 1 torch thread each")
    layout["reused"] = n_reused
    return workers, layout


__all__ = ["bench_jobs", "reused_rows", "training_layout"]
