"""Tabular learners online against the table beside the DQN, at equal environment steps, side by side in one run.

    python bench/bench_tabular.py                          # cubicle and Dallas Q3, 600 K env steps per learner
    python bench/bench_tabular.py --scenes cubicle --learners qlearning dyna
    python bench/bench_tabular.py --sweep                  # the small measurement behind the learners' defaults
    make bench-tabular

For each scene, every learner of ``--learners`` trains on the blueprint for ``--steps`` environment steps (the default
DQN's 600 K) in the same batched environment (256 robots, random connected pairs, the ``geodesic`` reward):

* ``qlearning``: tabular Q-learning (:mod:`dtradar_rl.tabular.qlearning`);
* ``dyna``: Dyna-Q with a learned model, planning and hindsight over targets (:mod:`dtradar_rl.tabular.dyna`);
* ``dqn``: the default DQN preset (``DEFAULT_PRESET``, what ``make train`` trains), and ``tuned``, its earlier default.

At ``--early`` steps and every ``--every`` steps the greedy policy is evaluated on ``--pairs`` seeded pairs of the
blueprint (``--eval-seed`` 2024, the pairs of ``make eval``): success rate and SPL (the learning curves; the
evaluation's time is not counted in the training time). After training each learner is evaluated on the blueprint
and on the dynamic twin, a tabular one twice: localising by fingerprint (what it senses) and with the true cell
(``oracle``), so the difference is what localisation errors cost. Also measured: how many cells share a fingerprint
and how many the dynamic twin's features localise elsewhere (:func:`dtradar_rl.tabular.fingerprints.ambiguity`).

Ratios: the env steps each learner needs before its curve first reaches a success of 0.9 and 0.99 (``--reach``),
DQN's steps over the learner's, and DQN's training seconds over the learner's. Every training is single-threaded
(``--threads``), one after the other. Writes ``results/<name>.{json,md,png}`` (``--out``, ``--name``).

``--sweep`` instead measures the learners' settings one at a time around their defaults on the cubicle (``--seeds``
per setting, evaluated on pairs of ``--sweep-pair-seed`` 7, not the reported 2024 ones):
``results/<name>_sweep.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from bench_tabular_report import markdown, plot, sweep_markdown  # beside this script in bench/ (on its path)

from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import evaluate, metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.tabular import dyna, qlearning
from dtradar_rl.tabular.fingerprints import ambiguity
from dtradar_rl.tabular.table_policy import TablePolicy, greedy_actions
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train

TABULAR = {"qlearning": (qlearning.QLearningConfig, qlearning.learn), "dyna": (dyna.DynaConfig, dyna.learn)}
DQN_PRESETS = {"dqn": DEFAULT_PRESET, "tuned": "tuned"}
LEARNERS = (*TABULAR, *DQN_PRESETS)


def label(learner: str) -> str:
    return (
        f"DQN ({DQN_PRESETS[learner]})"
        if learner in DQN_PRESETS
        else {"qlearning": "Q-learning", "dyna": "Dyna-Q"}[learner]
    )


def checkpoints(args) -> list[int]:
    every = list(range(args.every, args.steps + 1, args.every)) if args.every else []
    return sorted({c for c in [*args.early, *every, args.steps] if 0 < c <= args.steps})


def metrics_row(m) -> dict[str, float]:
    return {"success": m.success_rate, "spl": m.spl, "collisions": m.collisions}


# -- one learner's curve -----------------------------------------------------------------------------------------
def curve(learner: str, scene: str, bp, args, say) -> tuple[list[dict[str, Any]], Any, float, dict[str, Any]]:
    """Train ``learner`` on ``bp`` for ``args.steps``, evaluating the greedy policy at every checkpoint; returns the
    curve, the final policy, the training seconds (evaluations excluded) and the run's stats."""
    points, rows = checkpoints(args), []
    state: dict[str, Any] = {"next": 0}
    normalizer = Normalizer.fit(bp)

    def policy_of(q):
        if learner in TABULAR:
            return TablePolicy(bp, greedy_actions(q), normalizer, name=learner)
        cfg = state["cfg"]
        return Policy(q, cfg, normalizer, cfg.obs, {"dataset": {"name": bp.name, "version": bp.version}})

    def callback(q, env_steps: int, train_s: float) -> bool:
        if state["next"] < len(points) and env_steps >= points[state["next"]]:
            t0 = time.perf_counter()
            m, _ = evaluate(policy_of(q), bp, pairs=args.pairs, seed=args.eval_seed, latency=False)
            rows.append(
                {"env_steps": env_steps, "train_s": train_s, **metrics_row(m), "eval_s": time.perf_counter() - t0}
            )
            say(
                f"  {scene:10s} {learner:9s} {env_steps:>8d} steps {train_s:7.1f} s  success {m.success_rate:.3f}  "
                f"SPL {m.spl:.3f}"
            )
            while state["next"] < len(points) and env_steps >= points[state["next"]]:
                state["next"] += 1
        return False

    torch.set_num_threads(args.threads)
    if learner in TABULAR:
        cfg_cls, learn = TABULAR[learner]
        cfg = cfg_cls(
            scene=scene, seed=args.seed, total_env_steps=args.steps, threads=args.threads, save=False, verbose=False
        )
        result = learn(cfg, bp, normalizer=normalizer, callback=callback)
        return rows, result.policy, result.wall_s, {"config": cfg.to_dict(), **result.stats}
    cfg = config_for(
        DQN_PRESETS[learner],
        scene=scene,
        seed=args.seed,
        total_env_steps=args.steps,
        threads=args.threads,
        out=str(Path(args.runs) / DQN_PRESETS[learner] / scene / f"s{args.seed}"),
        verbose=False,
        checkpoint_every=0,
        save_replay=False,
    )
    state["cfg"] = cfg
    holder: dict[str, Any] = {}

    def keep(q, env_steps, train_s):
        holder["q"] = q
        return callback(q, env_steps, train_s)

    result = train(cfg, bp, normalizer=normalizer, callback=keep)
    return rows, policy_of(holder["q"]), result.wall_s, {"config": cfg.to_dict(), "env_steps": result.env_steps}


def first_reach(rows: list[dict[str, Any]], level: float) -> int | None:
    return next((r["env_steps"] for r in rows if r["success"] >= level), None)


# -- the benchmark -------------------------------------------------------------------------------------------------
def bench(args, say) -> dict[str, Any]:
    out: dict[str, Any] = {"scenes": {}}
    for scene in args.scenes:
        bp, dyn = load_dataset(f"{scene}/blueprint"), load_dataset(f"{scene}/dynamic")
        t0 = time.perf_counter()
        amb = {"blueprint": ambiguity(bp).to_dict(), "dynamic": ambiguity(bp, dyn).to_dict()}
        say(f"{scene}: fingerprints {amb} ({time.perf_counter() - t0:.1f} s)")
        scene_out: dict[str, Any] = {
            "datasets": {v: f"{d.name}@{(d.version or '-')[:12]}" for v, d in (("blueprint", bp), ("dynamic", dyn))},
            "ambiguity": amb,
            "learners": {},
        }
        for learner in args.learners:
            say(f"{scene}: {label(learner)} for {args.steps:,} env steps")
            rows, policy, train_s, stats = curve(learner, scene, bp, args, say)
            final: dict[str, Any] = {}
            modes = ["fingerprint", "oracle"] if learner in TABULAR else ["-"]
            for twin, ds in (("blueprint", bp), ("dynamic", dyn)):
                for mode in modes:
                    p = policy.with_localisation(mode) if learner in TABULAR else policy
                    m, _ = evaluate(p, ds, pairs=args.pairs, seed=args.eval_seed, latency=False)
                    final[f"{twin}/{mode}"] = metrics_row(m)
                    say(
                        f"  {scene:10s} {learner:9s} final on {twin:9s} ({mode:11s}) success {m.success_rate:.3f}  "
                        f"SPL {m.spl:.3f}  collisions {m.collisions:.2f}"
                    )
            scene_out["learners"][learner] = {
                "label": label(learner),
                "curve": rows,
                "train_s": train_s,
                "final": final,
                "reach": {str(lv): first_reach(rows, lv) for lv in args.reach},
                "stats": stats,
            }
        out["scenes"][scene] = scene_out
    return out


# -- the settings sweep -------------------------------------------------------------------------------------------
#: One setting at a time around each learner's defaults.
SWEEP = {
    "qlearning": [
        {},
        {"gamma": 0.0},
        {"gamma": 0.9},
        {"gamma": 0.99},
        {"lr": 0.5, "lr_end": -1.0},
        {"lr": 0.1, "lr_end": -1.0},
        {"lr": 1.0, "lr_end": 0.1},
        {"eps_decay_fraction": 0.1},
        {"eps_decay_fraction": 1.0},
        {"eps_start": 0.1, "eps_end": 0.1},
        {"eps_end": 0.2},
        {"num_envs": 64},
        {"num_envs": 1024},
    ],
    "dyna": [
        {},
        {"planning_steps": 0},
        {"planning_steps": 4},
        {"planning_targets": 64},
        {"hindsight": False},
        {"hindsight": False, "planning_steps": 4},
        {"hindsight": False, "planning_targets": 64},
        {"hindsight": False, "planning_steps": 0},
        {"gamma": 0.9},
        {"lr": 0.5, "lr_end": -1.0},
        {"num_envs": 64},
    ],
}


def sweep(args, say) -> dict[str, Any]:
    ds = load_dataset(f"{args.sweep_scene}/blueprint")
    pairs = sample_eval_pairs(ds, args.pairs, args.sweep_pair_seed)
    rows = []
    for learner, settings in SWEEP.items():
        steps = args.steps if learner == "qlearning" else args.sweep_dyna_steps
        for setting in settings:
            runs = []
            for seed in args.seeds:
                cfg_cls, learn = TABULAR[learner]
                cfg = cfg_cls(
                    scene=args.sweep_scene,
                    seed=seed,
                    total_env_steps=steps,
                    threads=1,
                    save=False,
                    verbose=False,
                    **setting,
                )
                r = learn(cfg, ds)
                m = metrics_from_rollouts(rollout(r.policy, ds, pairs))
                runs.append({"seed": seed, **metrics_row(m), "train_s": r.wall_s})
            row = {
                "learner": learner,
                "setting": setting or "default",
                "steps": steps,
                "success": float(np.mean([x["success"] for x in runs])),
                "success_sd": float(np.std([x["success"] for x in runs])),
                "spl": float(np.mean([x["spl"] for x in runs])),
                "train_s": float(np.mean([x["train_s"] for x in runs])),
                "runs": runs,
            }
            rows.append(row)
            say(
                f"  {learner:9s} {json.dumps(setting) if setting else 'default':45s} success {row['success']:.3f} "
                f"± {row['success_sd']:.3f}  SPL {row['spl']:.3f}  {row['train_s']:.1f} s"
            )
    return {"rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["cubicle", "dallas-q3"], help="twins with a dynamic variant")
    ap.add_argument("--learners", nargs="+", default=list(LEARNERS), choices=LEARNERS)
    ap.add_argument("--steps", type=int, default=600_000, help="env steps per learner (the paper's budget)")
    ap.add_argument("--every", type=int, default=60_000, help="evaluate the greedy policy every this many env steps")
    ap.add_argument(
        "--early", type=int, nargs="*", default=[2_560, 5_120, 10_240, 20_480, 40_960], help="and at these env steps"
    )
    ap.add_argument("--reach", type=float, nargs="+", default=[0.9, 0.99], help="success levels for the ratios")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--eval-seed", type=int, default=2024, help="seed of the evaluation pairs (make eval's)")
    ap.add_argument("--seed", type=int, default=0, help="seed of every training")
    ap.add_argument("--threads", type=int, default=1, help="torch threads of each training")
    ap.add_argument("--runs", default=str(run_dir("bench_tabular")), help="where the DQN runs go")
    ap.add_argument("--sweep", action="store_true", help="measure the tabular learners' settings instead")
    ap.add_argument("--sweep-scene", default="cubicle")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="--sweep: seeds per setting")
    ap.add_argument("--sweep-pair-seed", type=int, default=7, help="--sweep: seed of its evaluation pairs")
    ap.add_argument("--sweep-dyna-steps", type=int, default=5_120, help="--sweep: Dyna's budget (it learns early)")
    ap.add_argument("--out", default="results")
    ap.add_argument("--name", default="bench_tabular", help="stem of the result files")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    t_start = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - t_start:7.1f}s] {msg}", flush=True)

    m_start = machine()
    body = sweep(args, say) if args.sweep else bench(args, say)
    result = {
        "args": vars(args),
        **body,
        "machine": {"start": m_start, "end": machine()},
        "command": "python bench/bench_tabular.py " + " ".join(sys.argv[1:]),
        "wall_s": time.perf_counter() - t_start,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / (f"{args.name}_sweep" if args.sweep else args.name)
    write_atomic(stem.with_suffix(".json"), json.dumps(result, indent=2, default=str) + "\n")
    md = sweep_markdown(result) if args.sweep else markdown(result)
    write_atomic(stem.with_suffix(".md"), md)
    if not args.sweep:
        plot(result, stem.with_suffix(".png"))
    print(md, end="")
    print(f"results: {stem}.json, .md" + ("" if args.sweep else ", .png") + f" ({result['wall_s']:.0f} s)")


if __name__ == "__main__":
    main()
