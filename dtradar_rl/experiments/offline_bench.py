"""The offline-RL benchmark: d3rlpy algorithms x logged behaviour datasets x seeds, evaluated with our own rollouts.

    make offline-bench SCENE=cubicle                      # the full setting (long on 2 CPU cores)
    python -m dtradar_rl offline-bench --scene cubicle --seeds 0 --n-steps 2000   # a reduced one

1. The online reference: a DQN checkpoint (``--checkpoint``, else ``runs/<scene>/dqn/model.pt``, else one is trained
   with the ``tuned`` preset and ``--online-steps``) is evaluated on the blueprint and dynamic twins. It is also the
   greedy policy of the ``epsilon-greedy`` behaviour and of the mixture's third component.
2. Every behaviour in ``--behaviours`` logs ``--steps`` steps on the blueprint twin into the store
   (``<scene>/blueprint/<behaviour>``, reused when already logged with the same settings; see
   :mod:`dtradar_rl.offline.logged`). Its own success rate and mean return on those episodes are reported beside the
   algorithms trained on it.
3. Every algorithm in ``--algorithms`` (d3rlpy DiscreteCQL, DiscreteBCQ, DiscreteBC, DQN, DoubleDQN, NFQ) trains
   ``--n-steps`` updates on each dataset for every seed, through :func:`dtradar_rl.offline.trainer.train_offline` (same
   hyper-parameters as ``make offline``), and is evaluated on the same seeded (start, target) pairs of both twins:
   success rate, SPL and collisions per episode, unshielded.
   The (dataset, algorithm, seed) trainings run in ``--workers`` spawned processes, one torch thread each (default
   :func:`auto_workers`: one per core when the cores measurably work in parallel right now, else one after the
   other): a second torch thread in one training made it 6-40x slower whenever another process held a core, and on
   this shared 2-core VM two processes did 1.0x the updates of one beside three busy jobs, 1.56x beside one
   (``bench/bench_offline_speed.py``). A run's weights do not depend on the layout.
4. Off-policy evaluation beside the truth (``--no-fqe`` to skip): every trained agent's value on its logged
   dataset's episode starts, estimated by d3rlpy's FQE from the logged transitions alone (``--fqe-steps`` updates)
   and measured by rolling it out on the blueprint twin from the same (start, target) pairs with the logged reward
   and the same γ (``--fqe-gamma``, :mod:`dtradar_rl.offline.ope`); the Spearman rank correlation of the two across
   agents, overall and within each dataset.
5. ``bench.json`` (every run and the mean ± std over seeds, with the machine's load), ``bench.md`` (the table),
   ``bench.png`` (bars with the spread over seeds; the online DQN as a line) and ``bench_fqe.png`` (FQE against the
   true value, one point per agent, the rank correlation in the title) go to ``--out``.

Time, measured on the 2-core VM (``bench/bench_offline_speed.py``, one torch thread, load ~2): 6.1 ms per update
on average over the six algorithms (BC 3.0, CQL 7.3, BCQ 9.0, the others ~5.8), ~2 s per run beside its updates
(evaluation on both twins, saving), ~12 s of FQE per agent at 2000 FQE updates. The full setting (5 datasets x 6
algorithms x 3 seeds x 10 K updates) then takes ~1.6 h of training alone in one process (~1 h with two processes
on free cores), ~20 min more with FQE; 30 min per twin fits ~2.7 K updates per run in one process without FQE.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.files import write_atomic
from dtradar_data.store.logged import episode_stats
from dtradar_rl.evaluation.evaluate import METRICS, evaluate_twins, metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.offline.behaviours import BEHAVIOURS, behaviour_policy
from dtradar_rl.offline.config import ALGORITHMS, OfflineConfig, check_algorithm
from dtradar_rl.offline.formats import as_logged
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.ope import FQE_GAMMA, FQE_STEPS, episode_starts, fqe_estimate, true_value
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.config import Config, ConfigError
from dtradar_rl.task.runs import dqn_checkpoint
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.checkpoints import load_policy
from dtradar_rl.train.config import config_for

NAMES = {
    "cql": "DiscreteCQL",
    "bcq": "DiscreteBCQ",
    "bc": "DiscreteBC",
    "dqn": "DQN",
    "ddqn": "DoubleDQN",
    "nfq": "NFQ",
}


@dataclass(frozen=True)
class OfflineBenchConfig(Config):
    """Offline-RL benchmark: d3rlpy algorithms on every logged behaviour dataset of a scene, several seeds,
    evaluated on the blueprint and dynamic twins beside the online DQN and the behaviour itself."""

    scene: str = "cubicle"
    """scene whose blueprint twin is logged on (synthetic-<nx>x<ny> for a stand-in without a ray tracer)"""
    behaviours: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy", "mixture")
    """behaviour datasets to train on"""
    algorithms: tuple[str, ...] = ("cql", "bcq", "bc", "dqn", "ddqn", "nfq")
    """d3rlpy algorithms (cql, bcq, bc, dqn, ddqn, nfq)"""
    seeds: tuple[int, ...] = (0, 1, 2)
    """training seeds of every algorithm (the logged datasets are the same for all: seed 0)"""
    steps: int = 100_000
    """environment steps logged per behaviour"""
    n_steps: int = 10_000
    """d3rlpy updates per run"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the shortest-path move"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move"""
    checkpoint: str = ""
    """online DQN checkpoint (default runs/<scene>/dqn/model.pt when it is a memoryless agent, else a tuned one is
    trained into <out>/online_dqn)"""
    online_steps: int = 600_000
    """environment steps of the online DQN when it has to be trained (tuned preset)"""
    num_envs: int = 256
    """robots logging in parallel"""
    pairs: int = 500
    """seeded (start, target) pairs per evaluated twin"""
    variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins to evaluate on"""
    device: str = "cpu"
    """torch device of logging and training"""
    workers: int = 0
    """training processes side by side, one torch thread each (0 = auto: one per core when that many processes do
    proportionally more work right now, else 1; 1 = all in this process)"""
    fqe: bool = True
    """estimate every agent's value with d3rlpy's FQE and measure it on the twin (--no-fqe: skip both)"""
    fqe_steps: int = FQE_STEPS
    """FQE updates per agent (about 12 s each on 1 core at 2000)"""
    fqe_gamma: float = FQE_GAMMA
    """discount of the value FQE estimates and the rollouts measure (the agents train with 0.5, under which all
    reasonable agents are worth about the same; see dtradar_rl.offline.ope)"""
    out: str = ""
    """output folder (default results/offline_bench/<scene>)"""
    verbose: bool = True
    """print progress"""

    @property
    def out_dir(self) -> Path:
        return Path(self.out or f"results/offline_bench/{self.scene}")

    def validate(self) -> OfflineBenchConfig:
        for a in self.algorithms:
            check_algorithm(a)
        for b in self.behaviours:
            if b not in BEHAVIOURS:
                from dtradar_data.core.errors import unknown_name

                raise unknown_name("behaviour policy", b, BEHAVIOURS)
        if not self.seeds or not self.algorithms or not self.behaviours:
            raise ConfigError("--seeds, --algorithms and --behaviours must each list at least one value")
        if self.workers < 0:
            raise ConfigError("--workers must be >= 0 (0 = one per CPU core)")
        if not 0 < self.fqe_gamma <= 1:
            raise ConfigError(f"--fqe-gamma must be in (0, 1], got {self.fqe_gamma}")
        for name in ("steps", "n_steps", "pairs", "num_envs", "online_steps", "fqe_steps"):
            if getattr(self, name) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be >= 1")
        return self


def _memoryless(path: Path) -> bool:
    """A checkpoint the epsilon-greedy behaviour can act with (a memory agent's memory is not in a logged step)."""
    return path.is_file() and not getattr(load_policy(path).config, "memory_radius", 0)


def _online_checkpoint(cfg: OfflineBenchConfig, say) -> tuple[Path, dict[str, Any]]:
    path = Path(cfg.checkpoint) if cfg.checkpoint else dqn_checkpoint(cfg.scene)
    if cfg.checkpoint or _memoryless(path):
        return path, {"trained_here": False}
    own = cfg.out_dir / "online_dqn" / "model.pt"  # make train's default agent has a memory: train a tuned one
    if own.is_file():
        return own, {"trained_here": False}
    from dtradar_rl.train.dqn import train

    say(f"no memoryless online DQN at {path}: training one (tuned, {cfg.online_steps} env steps)")
    t0 = time.perf_counter()
    dqn_cfg = replace(
        config_for("tuned", scene=cfg.scene),
        total_env_steps=cfg.online_steps,
        device=cfg.device,
        out=str(cfg.out_dir / "online_dqn"),
        verbose=False,
    )
    result = train(dqn_cfg.validate())
    return result.checkpoint, {"trained_here": True, "train_s": time.perf_counter() - t0, "env_steps": result.env_steps}


def evaluate_behaviour(
    cfg: OfflineBenchConfig, behaviour: str, checkpoint: str | Path | None, twins: dict[str, Any], blueprint: Any
) -> dict[str, dict[str, float]]:
    """The behaviour policy itself, rolled out with our evaluation (same seeded pairs as the trained agents) on
    every twin: ``{variant: {success_rate, spl, collisions}}``."""
    log_cfg = LogConfig(
        scene=cfg.scene,
        behaviour=behaviour,
        shortest_prob=cfg.shortest_prob,
        epsilon=cfg.epsilon,
        checkpoint=str(checkpoint or ""),
    )
    bp = behaviour_policy(log_cfg.spec(), blueprint, obs=log_cfg.obs, seed=2024, device=cfg.device)
    out = {}
    for name, ds in twins.items():
        r = rollout(bp, ds, sample_eval_pairs(ds, cfg.pairs, 2024), device=cfg.device)
        out[name.split("/")[1]] = {m: float(v) for m, v in metrics_from_rollouts(r).to_dict().items() if m in METRICS}
    return out


def _row_metrics(rows: list[dict[str, Any]], variant_name: str) -> dict[str, float]:
    row = next(r for r in rows if r["dataset"] == variant_name and not r.get("shield"))
    return {m: float(row[m]) for m in METRICS}


def aggregate(values: list[float]) -> dict[str, float]:
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=0)), "n": int(len(v))}


def _finish(
    cfg: OfflineBenchConfig,
    online: dict[str, Any],
    datasets: dict[str, Any],
    runs: list[dict[str, Any]],
    m_start: dict[str, Any],
    t_start: float,
    plots: bool = True,
    layout: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Aggregate the runs so far (mean ± std over seeds) and write ``bench.{json,md}`` and (``plots``) the PNGs."""
    out = cfg.out_dir
    summary = []
    for beh in datasets:
        for algo in cfg.algorithms:
            rs = [r for r in runs if r["behaviour"] == beh and r["algorithm"] == algo]
            if not rs:
                continue
            entry = {
                "behaviour": beh,
                "algorithm": algo,
                "seeds": [r["seed"] for r in rs],
                "train_s": aggregate([r["train_s"] for r in rs]),
            }
            for v in cfg.variants:
                if all(v in r for r in rs):
                    entry[v] = {m: aggregate([r[v][m] for r in rs]) for m in METRICS}
            for k in ("fqe", "true_value"):
                if all(k in r for r in rs):
                    entry[k] = aggregate([r[k] for r in rs])
            summary.append(entry)
    result = {
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.__dict__.items()},
        "algorithms": {a: NAMES[a] for a in cfg.algorithms},
        "online_dqn": online,
        "datasets": datasets,
        "summary": summary,
        "runs": runs,
        "machine": {"start": m_start, "end": machine()},
        "layout": layout or {},
        "wall_s": time.perf_counter() - t_start,
    }
    if cfg.fqe:
        result["ope"] = ope_summary(runs, cfg)
    write_atomic(out / "bench.json", json.dumps(result, indent=2) + "\n")
    write_atomic(out / "bench.md", markdown(result))
    if plots:
        plot(result, out / "bench.png")
        if cfg.fqe:
            plot_fqe(result, out / "bench_fqe.png")
    return result


def spearman(x: list[float], y: list[float]) -> float | None:
    """Spearman's rank correlation of ``x`` and ``y`` (ties get their mean rank); None with fewer than 3 points or
    a constant side."""
    from scipy.stats import spearmanr

    if len(x) < 3 or len(set(x)) < 2 or len(set(y)) < 2:
        return None
    rho = float(spearmanr(x, y).statistic)
    return None if math.isnan(rho) else rho


def ope_summary(runs: list[dict[str, Any]], cfg: OfflineBenchConfig) -> dict[str, Any]:
    """FQE against the true value over every agent so far: the rank correlation, overall and per dataset."""
    got = [r for r in runs if "fqe" in r and "true_value" in r]
    per = {}
    for beh in dict.fromkeys(r["behaviour"] for r in got):
        rs = [r for r in got if r["behaviour"] == beh]
        per[beh] = {"spearman": spearman([r["fqe"] for r in rs], [r["true_value"] for r in rs]), "n": len(rs)}
    return {
        "spearman": spearman([r["fqe"] for r in got], [r["true_value"] for r in got]),
        "n": len(got),
        "per_dataset": per,
        "gamma": cfg.fqe_gamma,
        "fqe_steps": cfg.fqe_steps,
        "value": "mean discounted return (logged reward) from the logged episodes' (start, target) pairs, greedy and "
        "unshielded: FQE from the logged transitions, true by rollouts on the blueprint twin",
    }


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


def run_bench(cfg: OfflineBenchConfig) -> dict[str, Any]:
    """Run the benchmark of ``cfg`` and write ``bench.{json,md,png}``; returns the JSON object."""
    cfg = cfg.validate()
    say = print if cfg.verbose else (lambda *a, **k: None)
    t_start = time.perf_counter()
    out = cfg.out_dir
    out.mkdir(parents=True, exist_ok=True)
    m_start = machine()
    twins = {f"{cfg.scene}/{v}": load_dataset(f"{cfg.scene}/{v}") for v in cfg.variants}
    blueprint = twins.get(f"{cfg.scene}/blueprint") or load_dataset(f"{cfg.scene}/blueprint")
    needs_dqn = any(b in ("epsilon-greedy", "mixture") for b in cfg.behaviours)
    online: dict[str, Any] = {}
    ckpt = Path(cfg.checkpoint) if cfg.checkpoint else None
    if needs_dqn or cfg.checkpoint or _memoryless(dqn_checkpoint(cfg.scene)):
        ckpt, info = _online_checkpoint(cfg, say)
        policy = load_policy(ckpt, cfg.device)
        rows = [
            r
            for r, _, _ in evaluate_twins(
                policy,
                cfg.scene,
                cfg.variants,
                pairs=cfg.pairs,
                seed=2024,
                device=cfg.device,
                shield=False,
                datasets=twins,
            )
        ]
        online = {
            "checkpoint": str(ckpt),
            **info,
            **{r["dataset"].split("/")[1]: {m: float(r[m]) for m in METRICS} for r in rows},
        }
        say(
            f"online DQN {ckpt}: "
            + ", ".join(f"{v} success {online[v]['success_rate']:.3f}" for v in cfg.variants if v in online)
        )

    datasets: dict[str, Any] = {}
    jobs: list[BenchJob] = []
    for beh in cfg.behaviours:
        log_cfg = LogConfig(
            scene=cfg.scene,
            behaviour=beh,
            steps=cfg.steps,
            shortest_prob=cfg.shortest_prob,
            epsilon=cfg.epsilon,
            checkpoint=str(ckpt or ""),
            num_envs=cfg.num_envs,
            device=cfg.device,
            minari=False,
            verbose=cfg.verbose,
        )
        t0 = time.perf_counter()
        logged = log_dataset(log_cfg, blueprint)
        # recomputed, not read from the card: logs stored by an older dtradar counted end-of-log cuts as failures
        s = episode_stats(logged.table, (logged.meta.get("settings") or {}).get("max_steps"))
        datasets[beh] = {
            "name": logged.name,
            "version": logged.version,
            "tag": logged.tag,
            "steps": s["steps"],
            "episodes": s["episodes"],
            "cut_by_end_of_log": s["cut_by_end_of_log"],
            "success_rate": s["success_rate"],
            "reached_of_all": s["reached_of_all"],
            "mean_return": s["mean_return"],
            "log_s": time.perf_counter() - t0,
            "eval": evaluate_behaviour(cfg, beh, ckpt, twins, blueprint),
        }
        jobs += [
            BenchJob(
                behaviour=beh,
                algorithm=algo,
                seed=seed,
                logged=f"{logged.name}@{logged.version}",
                config=OfflineConfig(
                    scene=cfg.scene,
                    algorithm=algo,
                    seed=seed,
                    n_steps=cfg.n_steps,
                    pairs=cfg.pairs,
                    eval_variants=tuple(cfg.variants),
                    shield=False,
                    device=cfg.device,
                    num_envs=cfg.num_envs,
                    threads=1,
                    verbose=False,
                    out=str(out / "runs" / beh / algo / f"seed{seed}"),
                ),
                fqe_steps=cfg.fqe_steps if cfg.fqe else 0,
                fqe_gamma=cfg.fqe_gamma,
            )
            for algo in cfg.algorithms
            for seed in cfg.seeds
        ]

    workers, gain = (cfg.workers, None) if cfg.workers else auto_workers(len(jobs))
    workers = min(workers, max(1, len(jobs)))
    layout = {"jobs": len(jobs), "workers": workers, "torch_threads": 1, "parallel_gain": gain}
    say(f"{len(jobs)} trainings of {cfg.n_steps} updates in {workers} process(es), 1 torch thread each")
    runs: list[dict[str, Any]] = []

    def done(run: dict[str, Any]) -> None:
        runs.append(run)
        ope = f"; FQE {run['fqe']:.3f}, true {run['true_value']:.3f}" if "fqe" in run else ""
        say(
            f"[{time.perf_counter() - t_start:7.1f}s] {run['behaviour']:<15} {NAMES[run['algorithm']]:<12} "
            f"seed {run['seed']}: "
            + ", ".join(f"{v} {run[v]['success_rate']:.3f}" for v in cfg.variants if v in run)
            + f" ({run['train_s']:.1f} s training{ope})"
        )
        _finish(cfg, online, datasets, runs, m_start, t_start, plots=False, layout=layout)  # partial results survive

    runs = run_jobs(jobs, workers, done)
    runs.sort(key=lambda r: (cfg.behaviours.index(r["behaviour"]), cfg.algorithms.index(r["algorithm"]), r["seed"]))
    result = _finish(cfg, online, datasets, runs, m_start, t_start, layout=layout)
    say(markdown(result), end="")
    say(
        f"results: {out / 'bench.json'}, {out / 'bench.md'}, {out / 'bench.png'}"
        + (f", {out / 'bench_fqe.png'}" if cfg.fqe else "")
    )
    return result


def _pm(a: dict[str, float] | None, fmt: str = "{:.3f}") -> str:
    if not a:
        return "-"
    return fmt.format(a["mean"]) + (" ± " + fmt.format(a["std"]) if a["n"] > 1 else "")


def markdown(result: dict[str, Any]) -> str:
    """The benchmark table: one row per behaviour dataset, then one per algorithm trained on it (mean ± std)."""
    cfg = result["config"]
    variants = cfg["variants"]
    ope = result.get("ope")
    head = (
        "| dataset | policy | "
        + " | ".join(f"{v}: success | {v}: SPL | {v}: collisions/ep" for v in variants)
        + (" | FQE | true value" if ope else "")
        + " | train (s) |"
    )
    no_ope = " | - | -" if ope else ""
    lines = [
        f"Offline RL on `{cfg['scene']}` ({len(cfg['seeds'])} seed(s): {', '.join(map(str, cfg['seeds']))}; "
        f"{cfg['n_steps']} d3rlpy updates; {cfg['steps']} logged steps per behaviour; {cfg['pairs']} seeded "
        "pairs per twin, unshielded; mean ± std over seeds)",
        "",
        head,
        "|" + "---|" * (3 + 3 * len(variants) + (2 if ope else 0)),
    ]
    online = result.get("online_dqn") or {}
    if online:
        cells = []
        for v in variants:
            m = online.get(v) or {}
            cells += [f"{m.get(k, float('nan')):.3f}" if m else "-" for k in ("success_rate", "spl")]
            cells += [f"{m['collisions']:.2f}" if m else "-"]
        lines.append("| (online) | DQN, tuned | " + " | ".join(cells) + no_ope + " | - |")
    for beh, d in result["datasets"].items():
        ev = d.get("eval") or {}
        blank = " | ".join(
            f"{ev[v]['success_rate']:.3f} | {ev[v]['spl']:.3f} | {ev[v]['collisions']:.2f}" if v in ev else "- | - | -"
            for v in variants
        )
        lines.append(
            f"| `{d['name']}`@{d['tag']} | behaviour itself (its logged episodes on the blueprint: success "
            f"{d['success_rate']:.3f} of finished episodes, {d.get('reached_of_all', 0):.3f} of all; "
            f"mean return {d['mean_return']:.2f}, {d['episodes']} episodes, "
            f"{d.get('cut_by_end_of_log', 0)} cut by the end of logging) | "
            f"{blank}{no_ope} | - |"
        )
        for e in (e for e in result["summary"] if e["behaviour"] == beh):
            cells = []
            for v in variants:
                m = e.get(v) or {}
                cells += [_pm(m.get("success_rate")), _pm(m.get("spl")), _pm(m.get("collisions"), "{:.2f}")]
            if ope:
                cells += [_pm(e.get("fqe")), _pm(e.get("true_value"))]
            lines.append(
                f"| {beh} | {result['algorithms'][e['algorithm']]} | "
                + " | ".join(cells)
                + f" | {e['train_s']['mean']:.1f} |"
            )
    if ope:
        rho = "-" if ope["spearman"] is None else f"{ope['spearman']:.2f}"
        per = ", ".join(
            f"{b} {'-' if d['spearman'] is None else format(d['spearman'], '.2f')} ({d['n']})"
            for b, d in ope["per_dataset"].items()
        )
        lines += [
            "",
            f"FQE against the true value: Spearman rank correlation {rho} over {ope['n']} agents (per dataset: "
            f"{per}). Value = {ope['value']}; γ = {ope['gamma']}, {ope['fqe_steps']} FQE updates per agent.",
        ]
    mach = result["machine"]
    lines += [
        "",
        f"Machine: {describe(mach['start'])}; load average (1/5/15 min) at start "
        f"{_load(mach['start'])}, at end {_load(mach['end'])}; total wall time {result['wall_s']:.0f} s"
        + (
            f" ({result['layout']['jobs']} trainings in {result['layout']['workers']} process(es), one torch thread "
            "each" + _gain(result["layout"].get("parallel_gain")) + ")."
            if result.get("layout")
            else "."
        ),
    ]
    return "\n".join(lines) + "\n"


def _gain(g: float | None) -> str:
    return "" if g is None else f"; {g:.2f}x the work with one process per core than with one, measured at the start"


def _load(m: dict[str, Any]) -> str:
    la = m.get("load_average")
    return "/".join(f"{x:.1f}" for x in la) if la else "-"


def plot(result: dict[str, Any], path: Path) -> Path:
    """Success bars per dataset and algorithm, one panel per twin, error bars = std over seeds; online DQN dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = result["config"]["variants"]
    behs = list(result["datasets"])
    algos = list(result["algorithms"])
    fig, axes = plt.subplots(1, len(variants), figsize=(5.5 * len(variants), 4.2), squeeze=False)
    width = 0.8 / max(1, len(algos))
    for ax, v in zip(axes[0], variants):
        x = np.arange(len(behs))
        for k, a in enumerate(algos):
            means, stds = [], []
            for b in behs:
                e = next((e for e in result["summary"] if e["behaviour"] == b and e["algorithm"] == a), {})
                m = (e.get(v) or {}).get("success_rate") or {"mean": np.nan, "std": 0.0}
                means.append(m["mean"])
                stds.append(m["std"])
            ax.bar(
                x + (k - (len(algos) - 1) / 2) * width,
                means,
                width,
                yerr=stds,
                capsize=2,
                label=result["algorithms"][a],
            )
        beh_success = [
            ((result["datasets"][b].get("eval") or {}).get(v) or {}).get("success_rate", np.nan) for b in behs
        ]
        ax.scatter(x, beh_success, marker="x", color="k", zorder=3, label="behaviour itself")
        online = (result.get("online_dqn") or {}).get(v)
        if online:
            ax.axhline(online["success_rate"], color="k", ls="--", lw=1, label="online DQN")
        ax.set_xticks(x, behs, rotation=15)
        ax.set_ylim(0, 1.25)
        ax.set_ylabel("success rate")
        ax.set_title(f"{result['config']['scene']} → {v}")
    axes[0][-1].legend(fontsize=7, loc="upper right", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_fqe(result: dict[str, Any], path: Path) -> Path:
    """FQE's estimate against the true value, one point per trained agent (colour: algorithm, marker: dataset),
    the diagonal, and the Spearman rank correlation in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in result["runs"] if "fqe" in r and "true_value" in r]
    algos, behs = list(result["algorithms"]), list(result["datasets"])
    markers = "osD^vP*X"
    fig, ax = plt.subplots(figsize=(5.6, 4.8))
    for r in runs:
        k = algos.index(r["algorithm"])
        ax.scatter(
            r["true_value"], r["fqe"], color=f"C{k}", marker=markers[behs.index(r["behaviour"]) % len(markers)], s=28
        )
    if runs:
        vals = [r["true_value"] for r in runs] + [r["fqe"] for r in runs]
        lo, hi = min(vals), max(vals)
        pad = 0.05 * (hi - lo or 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.6", lw=1, ls="--", label="FQE = true")
    for k, a in enumerate(algos):
        ax.scatter([], [], color=f"C{k}", marker="o", label=result["algorithms"][a])
    for j, b in enumerate(behs):
        ax.scatter([], [], color="k", marker=markers[j % len(markers)], label=b)
    ope = result.get("ope") or {}
    rho = ope.get("spearman")
    ax.set_title(
        f"{result['config']['scene']}: FQE vs true value, Spearman ρ = {'-' if rho is None else f'{rho:.2f}'} "
        f"({len(runs)} agents)",
        fontsize=10,
    )
    ax.set_xlabel(f"true value (rollouts on the twin, γ = {ope.get('gamma', '-')})")
    ax.set_ylabel("FQE estimate (logged data only)")
    ax.legend(fontsize=7, loc="lower right", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


__all__ = [
    "ALGORITHMS",
    "BenchJob",
    "OfflineBenchConfig",
    "aggregate",
    "auto_workers",
    "markdown",
    "parallel_gain",
    "ope_summary",
    "plot",
    "plot_fqe",
    "run_bench",
    "run_job",
    "run_jobs",
    "spearman",
]
