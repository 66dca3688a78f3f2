"""The offline-RL benchmark: d3rlpy algorithms x logged dataset families x seeds, evaluated with our own rollouts and
scored on the normalised scale (0 = uniformly random moves, 100 = the shortest-path expert).

    make offline-bench SCENE=cubicle                      # the default: 5 families x 6 algorithms x 3 seeds
    python -m dtradar_rl offline-bench --scene cubicle --seeds 0 --n-steps 2000   # a reduced one

1. The datasets: every behaviour in ``--behaviours`` (default the five families of D4RL's names, ``random``,
   ``expert``, ``medium``, ``medium-replay``, ``mixed``; :mod:`dtradar_rl.offline.behaviours`) logs ``--steps``
   steps on the blueprint twin into the store (``<scene>/blueprint/<family>``, reused when already logged with the
   same settings, so ``make log SCENE=<scene> BEHAVIOUR=all`` beforehand is the same data; the medium agent is
   trained once and cached). The behaviour itself is rolled out like the trained agents (not ``medium-replay``,
   which is a replay buffer, not one policy) and its logged episodes' score read from its card.
2. The references: the normalised score's random and expert SPL on the evaluation pairs of every evaluated twin
   (:func:`dtradar_rl.evaluation.normalized.reference_scores`); with the default ``--pairs 500`` these are exactly the
   pairs and references of ``make eval`` and the datasets' cards. An online agent is evaluated beside them when one
   exists (``--checkpoint``, else ``runs/<scene>/dqn/model.pt`` of ``make train``); the older behaviours
   ``epsilon-greedy`` and ``mixture`` act with a memoryless one (a ``tuned`` DQN is trained into ``<out>/online_dqn``
   when there is none).
3. Every algorithm in ``--algorithms`` (d3rlpy DiscreteCQL, DiscreteBCQ, DiscreteBC, DQN, DoubleDQN, NFQ) trains
   ``--n-steps`` updates on each dataset for every seed, through :func:`dtradar_rl.offline.trainer.train_offline` (same
   hyper-parameters as ``make offline``), and is evaluated on the same seeded (start, target) pairs of both twins:
   normalised score, success rate, SPL and collisions per episode, unshielded.
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
5. ``bench.json`` (every run and the mean ± std over seeds, the references, the machine's load), ``bench.md`` (the
   normalised-score table per twin, then every metric), ``bench.png`` (score bars with the spread over seeds) and
   ``bench_fqe.png`` (FQE against the true value) go to ``--out`` (:mod:`dtradar_rl.experiments.offline_report`).

One benchmark writes an ``--out`` at a time (a second is refused, naming the first one's pid); each run's row is kept
in its run folder, so a benchmark that was interrupted, or lost a worker for good, and runs again trains only the
runs it had not finished (``--no-reuse``: all of them; :mod:`dtradar_rl.experiments.offline_jobs`).

The budget (``--n-steps``, ``--fqe-steps``) was chosen by measurement for 30 min of wall time per twin on this 2-core
machine: the cubicle took 29 min, a Dallas quadrant 27 min; what each
reaches is in docs/results/offline-first-benchmark.md.
"""

from __future__ import annotations

import copy
import json
import math
import threading
import time
from pathlib import Path
from typing import Any

from dtradar_data.core.files import write_atomic
from dtradar_data.store.logged import episode_stats
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.evaluation.normalized import reference_scores
from dtradar_rl.experiments.offline_bench_config import (  # re-exported: the benchmark's settings
    BENCH_FQE_STEPS,
    BENCH_UPDATES,
    EVAL_SEED,
    NAMES,
    NEED_ONLINE,
    OfflineBenchConfig,
)
from dtradar_rl.experiments.offline_figures import plot, plot_fqe
from dtradar_rl.experiments.offline_jobs import (
    BenchJob,
    auto_workers,
    check_ray,
    parallel_gain,
    run_job,
    run_jobs,
    run_jobs_on_ray,
    save_row,
)
from dtradar_rl.experiments.offline_online import online_reference
from dtradar_rl.experiments.offline_online import scores as _scores
from dtradar_rl.experiments.offline_plan import bench_jobs, reused_rows, training_layout
from dtradar_rl.experiments.offline_report import markdown, ope_summary, summarize
from dtradar_rl.experiments.offline_tabular import tabular_section
from dtradar_rl.experiments.offline_tabular_honest import honest_tabular_section
from dtradar_rl.offline.behaviours import behaviour_policy
from dtradar_rl.offline.config import ALGORITHMS
from dtradar_rl.offline.formats import as_logged
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.medium_agent import resolve_spec
from dtradar_rl.task.runs import held_out_folder
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import load_dataset


def evaluate_behaviour(
    log_cfg: LogConfig, twins: dict[str, Any], blueprint: Any, refs: dict[str, dict[str, float]], pairs: int
) -> dict[str, dict[str, float]]:
    """The behaviour of ``log_cfg`` itself, rolled out with our evaluation (same seeded pairs as the trained agents)
    on every twin: ``{variant: {normalized, success_rate, spl, collisions}}``; empty for ``medium-replay``, which is
    a training run's replay buffer, not one policy."""
    spec = resolve_spec(log_cfg, blueprint, say=lambda *a, **k: None)
    if not spec.used:
        return {}
    bp = behaviour_policy(spec, blueprint, obs=log_cfg.obs, seed=EVAL_SEED, device=log_cfg.device)
    out = {}
    for name, ds in twins.items():
        variant = name.split("/")[1]
        r = rollout(bp, ds, sample_eval_pairs(ds, pairs, EVAL_SEED), device=log_cfg.device)
        out[variant] = _scores(metrics_from_rollouts(r).to_dict(), refs[variant])
    return out


def _finish(
    cfg: OfflineBenchConfig,
    head: dict[str, Any],
    runs: list[dict[str, Any]],
    m_start: dict[str, Any],
    t_start: float,
    plots: bool = True,
    layout: dict[str, Any] | None = None,
    *,
    planned: int,
    complete: bool = False,
) -> dict[str, Any]:
    """Aggregate the runs so far (mean ± std over seeds) and write ``bench.{json,md}`` and (``plots``) the PNGs.
    A report written before the benchmark has finished (``complete`` False: after each run, while others, or the
    tabular section, are still to come) says so: ``"complete": false`` with the runs done of ``planned`` in the JSON,
    a first line in the Markdown; one killed there (kill -9) thus never reads as finished."""
    out = cfg.out_dir
    result = {
        "complete": complete,
        "runs_done": len(runs),
        "runs_planned": planned,
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.__dict__.items()},
        "algorithms": {a: NAMES[a] for a in cfg.algorithms} if cfg.deep else {},
        **head,
        "summary": summarize(runs, list(cfg.behaviours), list(cfg.algorithms), list(cfg.variants)),
        "runs": runs,
        "machine": {"start": m_start, "end": machine()},
        "layout": layout or {},
        "wall_s": time.perf_counter() - t_start,
    }
    if cfg.fqe and cfg.deep:
        result["ope"] = ope_summary(runs, cfg.fqe_gamma, cfg.fqe_steps)
    write_atomic(out / "bench.json", json.dumps(result, indent=2) + "\n")
    write_atomic(out / "bench.md", markdown(result))
    if plots:
        plot(result, out / "bench.png")
        if cfg.fqe and cfg.deep:
            plot_fqe(result, out / "bench_fqe.png")
    return result


def log_datasets(
    cfg: OfflineBenchConfig, ckpt: Path | None, twins: dict[str, Any], blueprint: Any, refs: dict[str, Any]
) -> tuple[dict[str, Any], dict[str, str]]:
    """Every dataset of ``cfg.behaviours`` logged (or reused) on the blueprint: its description for ``bench.json``
    (counts, its behaviour's own scores) and its ``name@version``."""
    datasets: dict[str, Any] = {}
    ids: dict[str, str] = {}
    for beh in cfg.behaviours:
        log_cfg = LogConfig(
            scene=cfg.scene,
            behaviour=beh,
            steps=cfg.steps,
            shortest_prob=cfg.shortest_prob,
            epsilon=cfg.epsilon,
            checkpoint=str(ckpt or "") if beh in NEED_ONLINE else "",
            num_envs=cfg.num_envs,
            device=cfg.device,
            minari=False,
            verbose=cfg.verbose,
            sensing=cfg.sensing,
            sensing_noise=cfg.sensing_noise,
        )
        t0 = time.perf_counter()
        logged = log_dataset(log_cfg, blueprint)
        # recomputed, not read from the card: logs stored by an older dtradar counted end-of-log cuts as failures
        s = episode_stats(logged.table, (logged.meta.get("settings") or {}).get("max_steps"))
        card_score = ((logged.meta.get("score") or {}).get("episodes") or {}).get("normalized")
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
            "logged_score": None if card_score is None or math.isnan(card_score) else float(card_score),
            "log_s": time.perf_counter() - t0,
            "eval": evaluate_behaviour(log_cfg, twins, blueprint, refs, cfg.pairs),
        }
        ids[beh] = f"{logged.name}@{logged.version}"
    return datasets, ids


def _tables(cfg: OfflineBenchConfig, ids, twins, refs, say, *, overlap: bool):
    """A callable giving ``(tabular section, seconds)``: computed now, or (``overlap``) in a thread of this process
    while the trainings run in other processes (the section is numpy, one core; it left a core idle for minutes
    when it ran before them). An error in the thread is raised by the callable."""
    if not cfg.tabular:
        return lambda: (None, 0.0)
    logged = {b: as_logged(i) for b, i in ids.items()}

    def compute():
        t0 = time.perf_counter()
        if cfg.honest:  # the tables followed through the localisation filter, under the benchmark's noise
            section = honest_tabular_section(
                cfg.scene, logged, twins, refs, sensing=cfg.sensing, noise=cfg.sensing_noise, pairs=cfg.pairs, say=say
            )
        else:
            section = tabular_section(cfg.scene, logged, twins, refs, pairs=cfg.pairs, say=say)
        return section, time.perf_counter() - t0

    if not overlap:
        out = compute()
        return lambda: out
    box: dict[str, Any] = {}

    def work():
        try:
            box["out"] = compute()
        except BaseException as e:  # noqa: BLE001  (handed to the main thread)
            box["error"] = e

    thread = threading.Thread(target=work, name="offline-bench-tables", daemon=True)
    thread.start()

    def result():
        thread.join()
        if "error" in box:
            raise box["error"]
        return box["out"]

    return result


def run_bench(cfg: OfflineBenchConfig) -> dict[str, Any]:
    """Run the benchmark of ``cfg`` and write ``bench.{json,md,png}``; returns the JSON object. ``--out`` is held for
    the whole benchmark: a second one into it is refused at once, naming this one's pid (its runs, rows and tables
    would interleave with these)."""
    cfg = cfg.validate()
    if cfg.executor == "ray":
        check_ray(cfg.ray_address)  # a dead cluster before the first log is stored, not after the last
    with held_out_folder(cfg.out_dir, f"running the offline benchmark of {cfg.scene}", what="benchmark"):
        return _run_bench(cfg)


def _run_bench(cfg: OfflineBenchConfig) -> dict[str, Any]:
    """The benchmark of ``cfg`` in its held ``--out``: the twins and their references, the online agent, the logged
    datasets, then the trainings (the finished ones reused) beside the tabular section, and the results written."""
    say = print if cfg.verbose else (lambda *a, **k: None)
    t_start = time.perf_counter()
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    m_start = machine()
    twins, blueprint, refs = _twins_and_references(cfg)
    ckpt, online = online_reference(cfg, twins, refs, say)
    datasets, ids = log_datasets(cfg, ckpt, twins, blueprint, refs)
    head = {"references": refs, "online_dqn": online, "datasets": datasets}
    head["setup_s"] = time.perf_counter() - t_start
    jobs = bench_jobs(cfg, ids)
    reused, todo = reused_rows(cfg, jobs, say)
    workers, layout = training_layout(cfg, todo, len(reused), say)
    # the tables run in this process: beside trainings that run elsewhere (worker processes, Ray), at the same time
    tables = _tables(cfg, ids, twins, refs, say, overlap=bool(todo) and (cfg.executor == "ray" or workers >= 2))
    runs: list[dict[str, Any]] = []
    done = _gatherer(cfg, jobs, refs, head, runs, m_start, t_start, layout, say)
    _train(cfg, reused, todo, workers, done)
    if cfg.tabular:
        head["tabular"], head["tabular_s"] = tables()
    runs.sort(key=lambda r: (cfg.behaviours.index(r["behaviour"]), cfg.algorithms.index(r["algorithm"]), r["seed"]))
    result = _finish(cfg, head, runs, m_start, t_start, layout=layout, planned=len(jobs), complete=True)
    _say_results(cfg, result, say)
    return result


def _twins_and_references(cfg: OfflineBenchConfig) -> tuple[dict[str, Any], Any, dict[str, dict[str, float]]]:
    """The evaluated twins by name, the blueprint the datasets are logged on (loaded again only when it is not
    evaluated), and each twin's random and expert references by variant."""
    twins = {f"{cfg.scene}/{v}": load_dataset(f"{cfg.scene}/{v}") for v in cfg.variants}
    blueprint = twins.get(f"{cfg.scene}/blueprint") or load_dataset(f"{cfg.scene}/blueprint")
    refs = {
        name.split("/")[1]: reference_scores(ds, pairs=cfg.pairs, seed=EVAL_SEED, device=cfg.device)
        for name, ds in twins.items()
    }
    return twins, blueprint, refs


def _gatherer(
    cfg: OfflineBenchConfig,
    jobs: list[BenchJob],
    refs: dict[str, dict[str, float]],
    head: dict[str, Any],
    runs: list[dict[str, Any]],
    m_start: dict[str, Any],
    t_start: float,
    layout: dict[str, Any],
    say,
):
    """The callable each finished run's row is handed to (``fresh=False``: a reused one): it keeps a fresh row in its
    run folder, scores the row, appends it to ``runs``, says it and writes the partial results."""
    job_of = {(j.behaviour, j.algorithm, j.seed): j for j in jobs}
    t_train, trained = time.perf_counter(), [0]  # the time left is the fresh trainings' mean pace so far

    def done(run: dict[str, Any], fresh: bool = True) -> None:
        if fresh:  # its row as the job returned it, before scoring: what a benchmark run again reuses
            save_row(job_of[run["behaviour"], run["algorithm"], run["seed"]], copy.deepcopy(run))
        for v in cfg.variants:
            if v in run:
                run[v] = _scores(run[v], refs[v])
        runs.append(run)
        ope = f"; FQE {run['fqe']:.3f}, true {run['true_value']:.3f}" if "fqe" in run else ""
        trained[0] += fresh
        left = (time.perf_counter() - t_train) / max(trained[0], 1) * (len(jobs) - len(runs)) if trained[0] else 0.0
        say(
            f"[{time.perf_counter() - t_start:7.1f}s] run {len(runs)}/{len(jobs)}, about {left / 60:.1f} min left: "
            f"{run['behaviour']:<15} {NAMES[run['algorithm']]:<12} "
            f"seed {run['seed']}: "
            + ", ".join(
                f"{v} {run[v]['normalized']:.1f} (success {run[v]['success_rate']:.3f})"
                for v in cfg.variants
                if v in run
            )
            + f" ({run['train_s']:.1f} s training{ope})"
        )
        _finish(cfg, head, runs, m_start, t_start, plots=False, layout=layout, planned=len(jobs))  # marked partial

    return done


def _train(
    cfg: OfflineBenchConfig, reused: dict[int, dict[str, Any]], todo: list[BenchJob], workers: int, done
) -> None:
    """The reused rows handed to ``done`` first, then the ``todo`` trainings run, on Ray or in ``workers``
    processes, each row handed to ``done`` as it comes."""
    for row in reused.values():
        done(row, fresh=False)
    if cfg.executor == "ray" and todo:
        run_jobs_on_ray(todo, cfg.ray_address, done)  # each row handed to done, which gathers them in runs
    elif todo:
        run_jobs(todo, workers, done)


def _say_results(cfg: OfflineBenchConfig, result: dict[str, Any], say) -> None:
    """``bench.md`` and the paths of the files written, on the console."""
    out = cfg.out_dir
    say(markdown(result), end="")
    say(
        f"results: {out / 'bench.json'}, {out / 'bench.md'}, {out / 'bench.png'}"
        + (f", {out / 'bench_fqe.png'}" if cfg.fqe and cfg.deep else "")
    )


__all__ = [
    "ALGORITHMS",
    "BENCH_FQE_STEPS",
    "BENCH_UPDATES",
    "BenchJob",
    "OfflineBenchConfig",
    "auto_workers",
    "evaluate_behaviour",
    "log_datasets",
    "parallel_gain",
    "run_bench",
    "run_job",
    "run_jobs",
]
