"""One navigation table: every twin x {the default agent, the classical planner} x measurement noise.

For each scene and seed, train the default preset (``--preset``, default ``DEFAULT_PRESET``) on the blueprint for
``--steps`` (the paper's 600 K; a run whose ``model.pt`` exists under ``--runs`` with the same preset and budget is
reused), then evaluate it and the fingerprint + breadth-first planner on 500 seeded pairs of the blueprint and the
dynamic twin (where the scene has one) under every ``--noise`` level: success, SPL, collisions, decision p50 / p99
and training time. Writes ``results/bench_nav.{json,md,png}`` (mean ± spread over seeds). SB3 DQN is measured by
``make bench-rl`` (its 300-s capped runs are too slow to repeat on every twin here).

    python bench/bench_nav.py --scenes cubicle meeting dallas-q1 dallas-q2 dallas-q3 dallas-q4 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.planner import planner_for_scene
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.checkpoints import load_policy
from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.viz.plots import _save, plt

GOALS = {"blueprint": (0.99, 0.95), "dynamic": (0.95, None)}  # success, SPL (issue: cities at the indoor standard)


def trained(scene: str, seed: int, args) -> tuple[Path, float | None]:
    out = Path(args.runs) / args.preset / scene / f"s{seed}"
    ckpt = out / "model.pt"
    cfg = config_for(
        args.preset,
        scene=scene,
        seed=seed,
        total_env_steps=args.steps,
        out=str(out),
        verbose=False,
        threads=args.threads,
        checkpoint_every=0,
        save_replay=False,
    )
    summary = out / "train.json"
    if ckpt.is_file() and summary.is_file():
        saved = json.loads(summary.read_text())
        if saved.get("preset") == args.preset and saved.get("steps") == args.steps:
            return ckpt, saved.get("train_s")
    result = train(cfg)
    write_atomic(summary, json.dumps({"preset": args.preset, "steps": args.steps, "train_s": result.wall_s}) + "\n")
    return result.checkpoint, result.wall_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--scenes", nargs="+", default=["cubicle", "meeting", "dallas-q1", "dallas-q2", "dallas-q3", "dallas-q4"]
    )
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--preset", default=DEFAULT_PRESET)
    ap.add_argument("--steps", type=int, default=600_000)
    ap.add_argument("--noise", nargs="+", default=["none", "realistic"])
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--threads", type=int, default=0, help="torch threads for training (0 = auto)")
    ap.add_argument("--runs", default=str(run_dir("bench_nav")))
    ap.add_argument("--out", default="results")
    ap.add_argument("--name", default="bench_nav", help="stem of the result files")
    args = ap.parse_args()
    torch.set_num_threads(1)  # the evaluations: 500 robots at once gain nothing from a second thread on 2 cores
    rows, m_start = [], machine()
    for scene in args.scenes:
        twins = {}
        for variant in ("blueprint", "dynamic"):
            try:
                twins[variant] = load_dataset(f"{scene}/{variant}")
            except DatasetNotFoundError:
                pass
        planner = planner_for_scene(scene)
        for seed in args.seeds:
            ckpt, train_s = trained(scene, seed, args)
            agents = {args.preset: load_policy(ckpt)}
            if seed == args.seeds[0]:
                agents["planner"] = planner  # no seed of its own
            for agent, policy in agents.items():
                for noise in args.noise:
                    for variant, ds in twins.items():
                        m, _ = evaluate(policy, ds, pairs=args.pairs, noise=noise)
                        rows.append(
                            {
                                "scene": scene,
                                "seed": seed,
                                "agent": agent,
                                "noise": noise,
                                "twin": variant,
                                "success": m.success_rate,
                                "spl": m.spl,
                                "collisions": m.collisions,
                                "p50_ms": m.latency_ms,
                                "p99_ms": m.latency_p99_ms,
                                "train_s": train_s if agent != "planner" else None,
                            }
                        )
                        print(
                            f"{scene:10s} s{seed} {agent:14s} {noise:9s} {variant:9s} success {m.success_rate:.3f}"
                            f" SPL {m.spl:.3f} collisions {m.collisions:.2f} p50 {m.latency_ms:.3f} ms",
                            flush=True,
                        )
    result = {"args": vars(args), "rows": rows, "machine": {"start": m_start, "end": machine()}, "goals": GOALS}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / args.name
    write_atomic(stem.with_suffix(".json"), json.dumps(result, indent=2) + "\n")
    md = markdown(result)
    write_atomic(stem.with_suffix(".md"), md)
    plot(result, stem.with_suffix(".png"))
    print(md, end="")
    print(f"results: {stem}.json, .md, .png")


def _groups(rows):
    keys = list(dict.fromkeys((r["scene"], r["agent"], r["noise"]) for r in rows))
    for k in keys:
        yield k, [r for r in rows if (r["scene"], r["agent"], r["noise"]) == k]


def _pm(values, fmt="{:.3f}"):
    v = np.asarray([x for x in values if x is not None], float)
    if v.size == 0:
        return "-"
    return fmt.format(v.mean()) + (f" ± {fmt.format(v.std())}" if v.size > 1 else "")


def markdown(result) -> str:
    a = result["args"]
    lines = [
        f"## Navigation on every twin ({a['pairs']} seeded pairs per twin, seeds {' '.join(map(str, a['seeds']))}, "
        f"{a['steps']:,} training steps; {describe(result['machine']['start'])})",
        "",
        "| twin | agent | noise | blueprint: success / SPL | dynamic: success / SPL / collisions | decision p50 / p99 "
        "(ms) | training (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for (scene, agent, noise), rs in _groups(result["rows"]):
        bp = [r for r in rs if r["twin"] == "blueprint"]
        dy = [r for r in rs if r["twin"] == "dynamic"]
        bp_cell = f"{_pm(r['success'] for r in bp)} / {_pm(r['spl'] for r in bp)}" if bp else "-"
        dy_cell = (
            (
                f"{_pm(r['success'] for r in dy)} / {_pm(r['spl'] for r in dy)} / "
                f"{_pm((r['collisions'] for r in dy), '{:.2f}')}"
            )
            if dy
            else "-"
        )
        lat = f"{_pm(r['p50_ms'] for r in rs)} / {_pm(r['p99_ms'] for r in rs)}"
        lines.append(
            f"| {scene} | {agent} | {noise} | {bp_cell} | {dy_cell} | {lat} | "
            f"{_pm((r['train_s'] for r in bp), '{:.0f}')} |"
        )
    lines += ["", "Goals: blueprint success ≥ 0.99 and SPL ≥ 0.95 on every twin, dynamic success ≥ 0.95 (Dallas Q3)."]
    return "\n".join(lines) + "\n"


def plot(result, path: Path) -> Path:
    groups = [(k, rs) for k, rs in _groups(result["rows"]) if k[1] != "planner"]
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(groups)), 4))
    for i, (_key, rs) in enumerate(groups):
        for j, (twin, colour) in enumerate((("blueprint", "C0"), ("dynamic", "C1"))):
            v = [r["success"] for r in rs if r["twin"] == twin]
            if v:
                ax.bar(
                    i + (j - 0.5) * 0.38,
                    np.mean(v),
                    0.38,
                    yerr=np.std(v) if len(v) > 1 else None,
                    color=colour,
                    label=twin if i == 0 else None,
                )
    ax.axhline(0.99, color="C0", ls=":", lw=1)
    ax.axhline(0.95, color="C1", ls=":", lw=1)
    ax.set_xticks(range(len(groups)), [f"{s}\n{n}" for (s, _, n), _ in groups], fontsize=7)
    ax.set_ylim(0.5, 1.01)
    ax.set_ylabel("success")
    ax.set_title(f"{result['args']['preset']}: success on every twin (dotted: goals)")
    ax.legend(loc="lower left")
    return _save(fig, path)


if __name__ == "__main__":
    main()
