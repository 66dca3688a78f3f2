"""Sweeps: train and evaluate every (scene, seed) pair, on Ray workers or one after another, into one table.

    python -m dtradar_rl sweep --scenes cubicle meeting --seeds 0 1 2           # local Ray, one run per core
    python -m dtradar_rl sweep --scenes cubicle --seeds 0 1 --executor serial    # no Ray
    python -m dtradar_rl sweep --scenes cubicle --ray-address auto               # an existing Ray cluster

Each run is the same as ``make train`` then ``make eval`` (:func:`~dtradar_rl.train.dqn.train`,
:func:`~dtradar_rl.evaluation.evaluate.evaluate_twins`), with its own output folder ``<out>/<scene>/seed<k>``; a Ray
task asks for ``threads`` CPUs and uses that many torch threads, so runs do not fight over cores. The results are
gathered into ``sweep.json``, ``sweep.md`` (mean and standard deviation over seeds per scene and evaluation case) and
``sweep.png`` (bars with the spread).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dtradar_data.core.errors import MissingDependencyError
from dtradar_data.core.files import write_atomic
from dtradar_data.core.ray_cluster import check_address_given, connect_ray, wait_for_cpus
from dtradar_rl.evaluation.evaluate import METRICS, evaluate_twins
from dtradar_rl.task.config import Config, ConfigError, check_unique, flag
from dtradar_rl.task.runs import run_dir
from dtradar_rl.train.config import DEFAULT_PRESET, PRESETS, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy


@dataclass(frozen=True)
class SweepConfig(Config):
    """Train and evaluate several scenes x seeds as one sweep (on Ray by default)."""

    scenes: tuple[str, ...] = ("cubicle",)
    """scenes to train on (their blueprint twin) and evaluate (their twins)"""
    seeds: tuple[int, ...] = (0, 1, 2)
    """training seeds"""
    preset: str = DEFAULT_PRESET
    """training preset (memory-escape-noise-margin, the default; memory-escape-noise, memory-escape, tuned, robust,
    memory, paper)"""
    total_env_steps: int = 0
    """training budget per run (0 = the preset's)"""
    variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins to evaluate on"""
    pairs: int = 500
    """seeded evaluation pairs per twin"""
    executor: Literal["ray", "serial"] = "ray"
    """ray (runs as Ray tasks; `pip install 'dtradar[ray]'`) or serial (one after another here)"""
    ray_address: str | None = None
    """an existing Ray cluster (e.g. auto or ray://head:10001); default: a local Ray on this machine's cores"""
    threads: int = 1
    """CPUs (and torch threads) per run"""
    out: str = str(run_dir("sweep"))
    """output folder: one sub-folder per run, plus sweep.json, sweep.md and sweep.png"""

    def validate(self) -> SweepConfig:
        if not self.scenes or not self.seeds:
            raise ConfigError("--scenes and --seeds must each name at least one value")
        check_unique(self.seeds, "seeds")  # --seeds 0 0 would count one run twice: a spread that is not one
        check_unique(self.scenes, "scenes")
        if any(k < 0 for k in self.seeds):
            raise ConfigError(f"{flag('seeds')} must be >= 0, got {' '.join(map(str, self.seeds))}")
        if self.preset not in PRESETS:
            raise ConfigError(f"{flag('preset')} {self.preset!r} is not a preset", hint=", ".join(PRESETS))
        if self.threads < 1 or self.pairs < 1 or self.total_env_steps < 0:
            raise ConfigError(f"{flag('threads')} and {flag('pairs')} must be >= 1, {flag('total_env_steps')} >= 0")
        check_address_given(self.ray_address, error=ConfigError)  # "" started a local Ray, as no --ray-address does
        if self.executor == "serial" and self.ray_address:
            raise ConfigError("--ray-address applies to --executor ray only")
        return self


def run_one(scene: str, seed: int, cfg: SweepConfig) -> dict[str, Any]:
    """One training run and its evaluation: ``{"scene", "seed", "train_s", "rows"}``."""
    import torch

    torch.set_num_threads(cfg.threads)
    overrides = {"total_env_steps": cfg.total_env_steps} if cfg.total_env_steps else {}
    dq = config_for(
        cfg.preset,
        scene=scene,
        seed=seed,
        threads=cfg.threads,
        verbose=False,
        out=str(Path(cfg.out) / scene / f"seed{seed}"),
        **overrides,
    )
    t0 = time.perf_counter()
    result = train(dq)
    train_s = time.perf_counter() - t0
    policy = load_policy(result.checkpoint)
    rows = [row for row, _, _ in evaluate_twins(policy, scene, cfg.variants, pairs=cfg.pairs, shield=False)]
    return {
        "scene": scene,
        "seed": seed,
        "train_s": round(train_s, 2),
        "env_steps": result.env_steps,
        "rows": rows,
        "checkpoint": str(result.checkpoint),
        "pid": os.getpid(),
    }


def _import_ray(instead: str = "serial"):
    """Ray, or the typed error naming how to install it and the executor ``instead`` that needs none (each command
    has its own: a sweep's is ``serial``, the offline benchmark's ``local``)."""
    try:
        import ray
    except ImportError as e:
        raise MissingDependencyError(
            "--executor ray needs Ray, which is not installed",
            hint=f"pip install 'dtradar[ray]', or use --executor {instead}",
        ) from e
    return ray


def sweep(cfg: SweepConfig) -> dict[str, Any]:
    """Run every (scene, seed) and write the gathered results; returns the ``sweep.json`` content."""
    cfg = cfg.validate()
    jobs = [(s, k) for s in cfg.scenes for k in cfg.seeds]
    t0 = time.perf_counter()
    if cfg.executor == "ray":
        ray = _import_ray()
        started = connect_ray(ray, cfg.ray_address)  # bounded: a dead address fails in seconds, not minutes
        try:
            wait_for_cpus(ray, cfg.threads, what=f"one run ({flag('threads')} {cfg.threads})", address=cfg.ray_address)
            task = ray.remote(num_cpus=cfg.threads, max_retries=2)(run_one)
            runs = ray.get([task.remote(s, k, cfg) for s, k in jobs])
        finally:
            if started:
                ray.shutdown()
    else:
        runs = [run_one(s, k, cfg) for s, k in jobs]
    summary = summarise(runs)
    result = {
        "config": dataclasses.asdict(cfg),
        "wall_s": round(time.perf_counter() - t0, 2),
        "runs": runs,
        "summary": summary,
    }
    write_report(result, Path(cfg.out))
    return result


def summarise(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean and standard deviation over seeds of each metric, per (scene, evaluated twin)."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for run in runs:
        for row in run["rows"]:
            groups[(run["scene"], row["dataset"])].append(row)
    out = []
    for (scene, dataset), rows in sorted(groups.items()):
        entry: dict[str, Any] = {"scene": scene, "evaluated_on": dataset, "seeds": len(rows)}
        for m in METRICS:
            values = np.array([r[m] for r in rows if m in r], dtype=float)
            entry[m] = {"mean": float(values.mean()), "std": float(values.std(ddof=1)) if len(values) > 1 else 0.0}
        out.append(entry)
    return out


def write_report(result: dict[str, Any], out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "sweep.json", json.dumps(result, indent=2) + "\n")
    cfg = result["config"]
    lines = [
        f"# Sweep: {', '.join(cfg['scenes'])} x seeds {', '.join(map(str, cfg['seeds']))} "
        f"({cfg['preset']} preset, {cfg['executor']}, {result['wall_s']} s)",
        "",
        "| trained on | evaluated on | seeds | success | SPL | collisions / episode |",
        "|---|---|---:|---|---|---|",
    ]
    for e in result["summary"]:
        cells = " | ".join(f"{e[m]['mean']:.3f} ± {e[m]['std']:.3f}" for m in METRICS)
        lines.append(f"| {e['scene']}/blueprint | {e['evaluated_on']} | {e['seeds']} | {cells} |")
    write_atomic(out / "sweep.md", "\n".join(lines) + "\n")
    _plot(result["summary"], out / "sweep.png")


def _plot(summary: list[dict[str, Any]], path: Path) -> None:
    from dtradar_rl.viz.plots import _save, plt

    fig, ax = plt.subplots(figsize=(max(5.0, 1.4 * len(summary) + 2), 4))
    labels = [f"{e['scene']} →\n{e['evaluated_on'].split('/')[-1]}" for e in summary]
    x = np.arange(len(summary))
    for i, m in enumerate(("success_rate", "spl")):
        ax.bar(
            x + (i - 0.5) * 0.35,
            [e[m]["mean"] for e in summary],
            0.35,
            yerr=[e[m]["std"] for e in summary],
            capsize=3,
            label=m.replace("_", " "),
        )
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("mean over seeds (± std)")
    ax.legend(loc="lower right")
    ax.set_title("sweep: success and SPL per trained scene and evaluated twin")
    fig.tight_layout()
    _save(fig, path)  # atomic, closes the figure
