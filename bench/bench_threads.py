"""How many torch threads the training loop should use: the default preset's training run, short, with one and with
two threads, on an idle machine and with one busy process beside it, several rounds side by side.

Each case trains the default preset (``make train``'s) for ``--steps`` environment steps from the same seed into a
scratch folder and reports its wall time and env steps/s; the cases alternate round by round, so a slow spell of the
machine lands on every case, and the median round is reported. This is the measurement behind
:func:`dtradar_rl.task.runtime.auto_threads` (what ``--threads 0`` picks). Writes
``results/bench_threads_<scene>.{json,md,png}``.

    python bench/bench_threads.py --scene cubicle            # make bench-threads SCENE=cubicle
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from dtradar_data.core.files import write_atomic
from dtradar_rl.task.runtime import auto_threads, describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.viz.plots import _save, plt

LOADS = ("idle", "one busy process")


def _spin(stop) -> None:  # one busy core, as another job on the machine
    x = 0
    while not stop.is_set():
        x = (x * 31 + 7) % 1_000_003


def timed_run(ds, scene: str, steps: int, threads: int) -> dict:
    """One short training run of the default preset with ``threads`` torch threads: wall time, updates, steps/s."""
    with tempfile.TemporaryDirectory(prefix="dtradar-bench-threads-") as out:
        cfg = config_for(
            DEFAULT_PRESET,
            scene=scene,
            total_env_steps=steps,
            learning_starts=min(10_000, steps // 4),
            out=out,
            threads=threads,
            checkpoint_every=0,
            save_replay=False,
            verbose=False,
        )
        t0 = time.perf_counter()
        result = train(cfg, dataset=ds)
        wall = time.perf_counter() - t0
    return {"wall_s": wall, "updates": result.updates, "steps_per_s": result.env_steps / wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cubicle")
    ap.add_argument("--steps", type=int, default=60_000, help="env steps per run (the default budget is 600 K)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds; every case once per round")
    ap.add_argument(
        "--busy-rounds",
        type=int,
        default=1,
        help="rounds with the busy process (two threads beside it can be 10-20x slower: one round is enough to see it)",
    )
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()
    ds = load_dataset(f"{args.scene}/blueprint")
    timed_run(ds, args.scene, 5_000, 1)  # imports, table builds and kernels warm before anything is timed
    runs: dict[str, dict[int, list[dict]]] = {load: {n: [] for n in args.threads} for load in LOADS}
    for r in range(args.rounds):
        for load in LOADS if r < args.busy_rounds else LOADS[:1]:
            stop = mp.Event()
            busy = mp.Process(target=_spin, args=(stop,), daemon=True) if load != "idle" else None
            if busy:
                busy.start()
            try:
                for n in args.threads:
                    res = timed_run(ds, args.scene, args.steps, n)
                    runs[load][n].append(res)
                    print(
                        f"round {r + 1}, {load}, {n} thread(s): {res['wall_s']:.1f} s, "
                        f"{res['steps_per_s']:,.0f} steps/s"
                    )
            finally:
                if busy:
                    stop.set()
                    busy.join()
    torch.set_num_threads(1)
    cases = [
        {
            "load": load,
            "threads": n,
            "wall_s_each": [round(x["wall_s"], 2) for x in runs[load][n]],
            "median_wall_s": round(float(np.median([x["wall_s"] for x in runs[load][n]])), 2),
            "median_steps_per_s": round(float(np.median([x["steps_per_s"] for x in runs[load][n]]))),
            "updates": runs[load][n][0]["updates"],
        }
        for load in LOADS
        for n in args.threads
    ]
    result = {
        "scene": args.scene,
        "preset": DEFAULT_PRESET,
        "steps": args.steps,
        "rounds": args.rounds,
        "busy_rounds": args.busy_rounds,
        "machine": machine(),
        "auto_threads_now": auto_threads(),
        "cases": cases,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    stem = args.out / f"bench_threads_{args.scene}"
    write_atomic(stem.with_suffix(".json"), json.dumps(result, indent=2) + "\n")
    md = markdown(result)
    write_atomic(stem.with_suffix(".md"), md)
    plot(result, stem.with_suffix(".png"))
    print(md)


def markdown(result) -> str:
    """The report: a heading, how the rounds ran and one row per case (every round's wall time; steps/s and the
    ratio from the median round). Thousands apart by a space and the ratio of more threads in bold, as the docs'
    results pages print them, so ``make results-pages`` re-renders their table unchanged."""
    base = {c["load"]: c["median_wall_s"] for c in result["cases"] if c["threads"] == 1}
    lines = [
        f"# Training threads: {result['preset']} on {result['scene']}/blueprint, {result['steps']:,} env steps "
        f"({describe(result['machine'])})",
        "",
        f"Median of {result['rounds']} rounds idle and {result['busy_rounds']} beside the busy process, cases "
        "alternating; env steps/s and the ratio to one thread from the median run.",
        "",
        "| machine | torch threads | wall time per run (s) | env steps/s | vs 1 thread |",
        "|---|---:|---|---:|---:|",
    ]
    for c in result["cases"]:
        ratio = f"{base[c['load']] / c['median_wall_s']:.2f}×"
        steps = f"{c['median_steps_per_s']:,}".replace(",", " ")
        lines.append(
            f"| {c['load']} | {c['threads']} | {', '.join(f'{w:.1f}' for w in c['wall_s_each'])} | "
            f"{steps} | {ratio if c['threads'] == 1 else f'**{ratio}**'} |"
        )
    return "\n".join(lines) + "\n"


def plot(result, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(5.5, 3.4))
    threads = sorted({c["threads"] for c in result["cases"]})
    width = 0.8 / len(threads)
    for k, n in enumerate(threads):
        cs = [c for c in result["cases"] if c["threads"] == n]
        ax.bar([i + k * width for i in range(len(cs))], [c["median_steps_per_s"] for c in cs], width, label=f"{n}")
    ax.set_xticks([i + width * (len(threads) - 1) / 2 for i in range(len(LOADS))], list(LOADS))
    ax.set_ylabel("env steps/s (training, median)")
    ax.legend(title="torch threads", fontsize=8)
    ax.set_title(f"{result['preset']} on {result['scene']}", fontsize=9)
    return _save(fig, path)


if __name__ == "__main__":
    main()
