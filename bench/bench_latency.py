"""One robot's decision time, steady or not: p50 and p99 over 1 000 greedy decisions, with one and with two torch
threads, on an idle machine and with one busy process beside it, several repeated runs side by side.

The agent is a trained checkpoint (``--checkpoint``, default ``runs/<scene>/dqn/model.pt``; a short run of the
default preset is trained there first when it is missing) and the classical planner of the same scene. Each case
is run ``--repeats`` times in one process, alternating, so a slow spell of the machine lands on every case. Writes
``results/bench_latency_<scene>.{json,md,png}``.

    python bench/bench_latency.py --scene cubicle          # make bench-latency SCENE=cubicle
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.planner import planner_for_scene
from dtradar_rl.evaluation.evaluate import LATENCY_DECISIONS, decision_latency_ms
from dtradar_rl.task.runs import dqn_checkpoint
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.plots import _save, plt

GOAL_P50_MS, GOAL_P99_MS, PAPER_MS = 0.1, 0.5, 17.0


def _spin(stop) -> None:  # one busy core, as another job on the machine
    x = 0
    while not stop.is_set():
        x = (x * 31 + 7) % 1_000_003


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cubicle")
    ap.add_argument("--checkpoint", default="")
    ap.add_argument("--repeats", type=int, default=5, help="runs of every case")
    ap.add_argument("--decisions", type=int, default=LATENCY_DECISIONS)
    ap.add_argument("--out", default="results")
    args = ap.parse_args()
    ckpt = Path(args.checkpoint or dqn_checkpoint(args.scene))
    if not ckpt.is_file():
        print(f"no checkpoint at {ckpt}: training the default preset for 100 K steps first")
        ckpt = train(config_for(scene=args.scene, total_env_steps=100_000, out=str(ckpt.parent))).checkpoint
    ds = load_dataset(f"{args.scene}/blueprint")
    agents = {"agent": load_policy(ckpt), "planner": planner_for_scene(args.scene)}
    m_start = machine()
    rows = []
    for load in ("idle", "one busy process"):
        stop = mp.Event()
        busy = mp.Process(target=_spin, args=(stop,), daemon=True) if load != "idle" else None
        if busy:
            busy.start()
            time.sleep(1.0)
        try:
            for rep in range(args.repeats):
                for name, policy in agents.items():
                    for threads in (1, 2):
                        p50, p99 = decision_latency_ms(policy, ds, repeats=args.decisions, threads=threads)
                        rows.append(
                            {"policy": name, "threads": threads, "load": load, "run": rep, "p50_ms": p50, "p99_ms": p99}
                        )
                        print(
                            f"{name:8s} {threads} thread(s), {load:16s} run {rep}: p50 {p50:.3f} ms, p99 {p99:.3f} ms"
                        )
        finally:
            if busy:
                stop.set()
                busy.join()
    result = {
        "scene": args.scene,
        "checkpoint": str(ckpt),
        "decisions": args.decisions,
        "rows": rows,
        "machine": {"start": m_start, "end": machine()},
        "goal": {"p50_ms": GOAL_P50_MS, "p99_ms": GOAL_P99_MS},
        "paper_ms": PAPER_MS,
    }
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f"bench_latency_{args.scene}"
    write_atomic(stem.with_suffix(".json"), json.dumps(result, indent=2) + "\n")
    md = markdown(result)
    write_atomic(stem.with_suffix(".md"), md)
    plot(result, stem.with_suffix(".png"))
    print(md, end="")
    print(f"results: {stem}.json, .md, .png")


def _cases(result):
    keys = sorted({(r["policy"], r["threads"], r["load"]) for r in result["rows"]}, key=lambda k: (k[0], k[2], k[1]))
    for k in keys:
        yield k, [r for r in result["rows"] if (r["policy"], r["threads"], r["load"]) == k]


def markdown(result, goal: bool = True) -> str:
    """The report: a heading, one row per case with every run's p50 and p99, and the goal. ``goal=False`` leaves out
    the goal-met column (a page that states its own goal, or none)."""
    head = "| policy | torch threads | machine | p50 (ms), each run | p99 (ms), each run | worst p50 / p99 |"
    lines = [
        f"## Decision time on {result['scene']} ({result['decisions']} decisions per run, batch 1; "
        f"{describe(result['machine']['start'])})",
        "",
        head + (" goal met |" if goal else ""),
        "|---" * (7 if goal else 6) + "|",
    ]
    for (name, threads, load), rs in _cases(result):
        p50 = [r["p50_ms"] for r in rs]
        p99 = [r["p99_ms"] for r in rs]
        met = max(p50) <= GOAL_P50_MS and max(p99) <= GOAL_P99_MS
        lines.append(
            f"| {name} | {threads} | {load} | {' '.join(f'{v:.3f}' for v in p50)} | "
            f"{' '.join(f'{v:.3f}' for v in p99)} | {max(p50):.3f} / {max(p99):.3f} |"
            + (f" {'yes' if met else 'no'} |" if goal else "")
        )
    lines += ["", f"Goal: p50 ≤ {GOAL_P50_MS} ms and p99 ≤ {GOAL_P99_MS} ms in every run; the paper: {PAPER_MS} ms."]
    return "\n".join(lines) + "\n"


def markdown_twins(results: list[dict]) -> str:
    """Several twins' runs as one table (a twin column first, no worst or goal column): each case of each run, in the
    runs' order."""
    lines = [
        "| twin | policy | torch threads | machine | p50 (ms), each run | p99 (ms), each run |",
        "|---" * 6 + "|",
    ]
    for result in results:
        for (name, threads, load), rs in _cases(result):
            p50 = " ".join(f"{r['p50_ms']:.3f}" for r in rs)
            p99 = " ".join(f"{r['p99_ms']:.3f}" for r in rs)
            lines.append(f"| {result['scene']} | {name} | {threads} | {load} | {p50} | {p99} |")
    return "\n".join(lines) + "\n"


def plot(result, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(9, 4))
    labels, p50s, p99s = [], [], []
    for (name, threads, load), rs in _cases(result):
        labels.append(f"{name}\n{threads} thr, {load}")
        p50s.append([r["p50_ms"] for r in rs])
        p99s.append([r["p99_ms"] for r in rs])
    x = np.arange(len(labels))
    for i in x:
        ax.scatter(np.full(len(p50s[i]), i - 0.1), p50s[i], color="C0", s=14, label="p50" if i == 0 else None)
        ax.scatter(np.full(len(p99s[i]), i + 0.1), p99s[i], color="C3", s=14, label="p99" if i == 0 else None)
    ax.axhline(GOAL_P50_MS, color="C0", ls=":", lw=1)
    ax.axhline(GOAL_P99_MS, color="C3", ls=":", lw=1)
    ax.set_yscale("log")
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("ms per decision (log)")
    ax.set_title(f"Decision time, {result['scene']}: every run (dotted: goals)")
    ax.legend()
    return _save(fig, path)


if __name__ == "__main__":
    main()
