"""Navigation that survives change (issue 12): learned agents beside the classical baseline, and twin updates.

For each scene and seed: train the ``robust`` and ``memory`` presets on the blueprint (``--steps``, default the
paper's 600 K; a run whose ``model.pt`` exists under ``--runs`` is reused), evaluate them zero-shot on the blueprint and
the dynamic twin beside the fingerprint + breadth-first planner (:mod:`dtradar_rl.agents.planner`), then fine-tune the
memory agent on the dynamic twin for ``--seconds`` against training from scratch (:mod:`dtradar_rl.experiments.adapt`).
Writes
``results/bench_dynamic.{json,md}`` (mean and spread over seeds) and ``results/bench_dynamic_adapt_<scene>.png``.

    python bench/bench_dynamic.py --scenes cubicle meeting --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.experiments.adapt import AdaptConfig, adapt, first_time_at
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.plots import plot_adapt_seeds


def machine_state() -> str:
    return describe(machine())


def spread(values: list[float]) -> str:
    v = np.asarray(values, float)
    return f"{v.mean():.3f} ± {v.std():.3f}" if v.size > 1 else f"{v.mean():.3f}"


def main() -> None:
    args = _parser().parse_args()
    runs, out = Path(args.runs), Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, adapt_rows, train_s = [], [], {}
    for scene in args.scenes:
        twins = {v: load_dataset(f"{scene}/{v}") for v in ("blueprint", "dynamic")}
        rows += _planner_rows(scene, twins, args)
        for seed in args.seeds:
            for preset in args.presets:
                rows += _agent_rows(scene, seed, preset, twins, runs, train_s, args)
        for seed in args.seeds if args.adapt_seeds is None else args.adapt_seeds:
            adapt_rows.append(_adapted(scene, seed, runs, out, args))
    _write(rows, adapt_rows, train_s, args, out)


def _parser() -> argparse.ArgumentParser:
    """The options; the module's docstring is the ``--help`` text."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["cubicle", "meeting"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--presets", nargs="+", default=["robust", "memory"])
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--steps", type=int, default=600_000, help="training budget of each agent (the paper's: 600K)")
    ap.add_argument("--seconds", type=float, default=20.0, help="fine-tuning (and from-scratch) training seconds")
    ap.add_argument("--adapt-seeds", nargs="*", type=int, default=None, help="seeds to adapt (default: --seeds)")
    ap.add_argument("--runs", default=str(run_dir("bench_dynamic")))
    ap.add_argument("--out", default="results")
    ap.add_argument("--name", default="bench_dynamic", help="stem of the result files")
    return ap


def _planner_rows(scene: str, twins: dict, args) -> list[dict]:
    """The classical planner on both twins; it needs no training, so it has no seed."""
    rows = []
    planner = FingerprintPlanner(twins["blueprint"])
    for v, ds in twins.items():
        m, _ = evaluate(planner, ds, pairs=args.pairs, latency=True)
        rows.append({"scene": scene, "agent": "planner", "seed": None, "twin": v, **m.to_dict()})
        print(f"{scene} planner -> {v}: success {m.success_rate:.3f} SPL {m.spl:.3f}", flush=True)
    return rows


def _agent_rows(scene: str, seed: int, preset: str, twins: dict, runs: Path, train_s: dict, args) -> list[dict]:
    """One preset and seed on both twins, zero-shot from the blueprint; trained first unless its ``model.pt`` is
    there (a fresh training's seconds and machine go into ``train_s``)."""
    run = runs / scene / preset / f"seed{seed}"
    if not (run / "model.pt").exists():
        state = machine_state()
        result = train(
            config_for(preset, scene=scene, seed=seed, out=str(run), verbose=False, total_env_steps=args.steps)
        )
        train_s[f"{scene}/{preset}/{seed}"] = {"wall_s": result.wall_s, "machine": state}
    policy = load_policy(run / "model.pt")
    rows = []
    for v, ds in twins.items():
        m, _ = evaluate(policy, ds, pairs=args.pairs, latency=True)
        rows.append(
            {
                "scene": scene,
                "agent": preset,
                "seed": seed,
                "twin": v,
                **m.to_dict(),
                "train_s": policy.meta["stats"].get("wall_s"),
            }
        )
        print(f"{scene} {preset} seed {seed} -> {v}: success {m.success_rate:.3f} SPL {m.spl:.3f}", flush=True)
    return rows


def _adapted(scene: str, seed: int, runs: Path, out: Path, args) -> dict:
    """The twin update: the memory agent of ``seed`` fine-tuned on the dynamic twin against training from scratch;
    its curves, and its figure copied beside the results."""
    state = machine_state()
    t0 = time.perf_counter()
    res = adapt(
        AdaptConfig(
            scene=scene,
            checkpoint=str(runs / scene / "memory" / f"seed{seed}" / "model.pt"),
            seconds=args.seconds,
            pairs=args.pairs,
            seed=seed,
            verbose=False,
            out=str(runs / scene / "adapt" / f"seed{seed}"),
        )
    )
    row = {"scene": scene, "seed": seed, "curves": res.curves, "machine": state, "wall_s": time.perf_counter() - t0}
    shutil.copy(res.out_dir / "curve.png", out / f"{args.name}_adapt_{scene}_seed{seed}.png")
    print(res.markdown, flush=True)
    return row


def _write(rows: list[dict], adapt_rows: list[dict], train_s: dict, args, out: Path) -> None:
    """The Markdown (and, through :func:`report`, the per-scene figures), then the JSON with the machine at the end,
    then the Markdown printed."""
    md = report(rows, adapt_rows, args)
    write_atomic(out / f"{args.name}.md", md)
    write_atomic(
        out / f"{args.name}.json",
        json.dumps(
            {"args": vars(args), "rows": rows, "adapt": adapt_rows, "train": train_s, "machine_end": machine_state()},
            indent=2,
            default=str,
        )
        + "\n",
    )
    print(md)


def report(rows, adapt_rows, args) -> str:
    head = (
        f"Zero-shot (trained on the blueprint), mean ± std over seeds {', '.join(map(str, args.seeds))}; "
        f"{args.pairs} seeded pairs per twin:"
    )
    lines = [
        head,
        "",
        (
            "| scene | agent | blueprint → blueprint: success / SPL | → dynamic: success / SPL | "
            "collisions/ep (dynamic) | decision (ms) |"
        ),
        "|---|---|---|---|---|---|",
    ]
    for scene in args.scenes:
        for agent in ["planner", *args.presets]:
            sel = {
                t: [r for r in rows if r["scene"] == scene and r["agent"] == agent and r["twin"] == t]
                for t in ("blueprint", "dynamic")
            }
            if not sel["dynamic"]:
                continue

            def f(t, k, sel=sel):
                return spread([r[k] for r in sel[t]])

            lines.append(
                f"| {scene} | {agent} | {f('blueprint', 'success_rate')} / {f('blueprint', 'spl')} | "
                f"{f('dynamic', 'success_rate')} / {f('dynamic', 'spl')} | {f('dynamic', 'collisions')} | "
                f"{np.median([r['latency_ms'] for r in sel['dynamic']]):.3f} |"
            )
    if adapt_rows:
        lines += [
            "",
            f"Twin update on the dynamic twin ({args.seconds:g} s of training, memory agent as the start):",
            "",
            "| scene | seed | run | success at 0 s | success / SPL at the end | s to ≥ 0.95 | s to ≥ 0.99 |",
            "|---|---|---|---|---|---|---|",
        ]
        for a in adapt_rows:
            for run, curve in a["curves"].items():
                t95, t99 = first_time_at(curve, 0.95), first_time_at(curve, 0.99)
                lines.append(
                    f"| {a['scene']} | {a['seed']} | {run} | {curve[0]['success_rate']:.3f} | "
                    f"{curve[-1]['success_rate']:.3f} / {curve[-1]['spl']:.3f} | "
                    f"{'-' if t95 is None else f'{t95:.1f}'} | {'-' if t99 is None else f'{t99:.1f}'} |"
                )
        for scene in args.scenes:
            runs: dict[str, list] = {}
            for a in adapt_rows:
                if a["scene"] == scene:
                    for run, c in a["curves"].items():
                        runs.setdefault(run, []).append(c)
            if runs:
                plot_adapt_seeds(
                    runs,
                    Path(args.out) / f"{args.name}_adapt_{scene}.png",
                    title=f"{scene}/dynamic: success vs training seconds, seeds "
                    f"{', '.join(str(a['seed']) for a in adapt_rows if a['scene'] == scene)}",
                )
    return "\n".join(lines) + "\n"


def adapt_table(result: dict) -> str:
    """The twin update of the JSON's ``adapt`` rows: per scene and seed, the memory agent's zero-shot success, the
    fine-tune with the expert loss (first evaluation at >= 0.99, in bold, and success (SPL) at the end), the plain DQN
    fine-tune (first >= 0.99 and success at the end) and training from scratch with the expert loss (at the end)."""
    end = f"{result['args']['seconds']:g} s"

    def first(curve) -> str:
        t = first_time_at(curve, 0.99)
        return "never" if t is None else f"{t:.1f} s"

    lines = [
        f"| scene | seed | zero-shot (0 s) | fine-tune + expert loss: first ≥ 0.99 / at {end} (SPL) | plain DQN "
        f"fine-tune: first ≥ 0.99 / at {end} | from scratch + expert loss: at {end} |",
        "|---|---|---:|---|---|---:|",
    ]
    for a in result["adapt"]:
        ft, plain, scratch = (a["curves"].get(k) for k in ("finetune", "finetune-dqn", "scratch"))
        plain_cell = f"{first(plain)} / {plain[-1]['success_rate']:.3f}" if plain else "-"
        scratch_cell = f"{scratch[-1]['success_rate']:.3f}" if scratch else "-"
        lines.append(
            f"| {a['scene']} | {a['seed']} | {ft[0]['success_rate']:.3f} | **{first(ft)}** / "
            f"{ft[-1]['success_rate']:.3f} ({ft[-1]['spl']:.3f}) | {plain_cell} | {scratch_cell} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
