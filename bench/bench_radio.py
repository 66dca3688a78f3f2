"""What the radio contributes: the default agent on every twin with each sensing, under each receiver noise level.

For each ``--scenes`` twin (its blueprint, and its dynamic twin where built) the default agent (the radio filter of
``dtradar_rl.agents.radio_filter``, its map the blueprint) is evaluated on ``--pairs`` seeded start/target pairs with
every ``--sensings`` setting (``radio``: the default, own-cell radio with proximity and odometry; ``no-angles``,
``no-delay``, ``no-gain``, ``no-phase``: without one group of radio features; ``rssi``: the gain alone; ``no-radio``:
proximity and odometry only) under every ``--noises`` level; beside it the privileged DQN (told its position) where
``runs/<scene>/dqn/model.pt`` is trained. SPL is measured from the true start on the twin navigated. Along the first
``--track-steps`` steps of each episode it records how far the filter's most likely cell is from the true one.

Writes ``<out>.json`` (every row, the localisation errors, the command and the machine), ``<out>.md``, ``<out>.png``
(SPL by sensing and noise, per twin) and ``<out>_localisation.png`` (localisation error along the episode); with
``--page`` also a results page for the docs, generated from the JSON.

    python bench/bench_radio.py --scenes cubicle meeting office --page docs/results/radio.md
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent
from dtradar_rl.evaluation.evaluate import evaluate, sample_eval_pairs
from dtradar_rl.task.runs import dqn_checkpoint
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.sensing import SENSINGS
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.plots import _save, plt

SCENES = ("cubicle", "meeting", "office", "dallas-q1", "dallas-q2", "dallas-q3", "dallas-q4", "sionna-munich-10tx")
HONEST = tuple(name for name, s in SENSINGS.items() if s.honest and name != "radio-no-proximity")
NOISES = ("none", "realistic", "2x")
#: The goals the default agent (radio, realistic noise) is held to: success and SPL on each twin.
GOALS = {
    ("cubicle", "blueprint"): (0.99, 0.97),
    ("meeting", "blueprint"): (0.99, 0.97),
    ("office", "blueprint"): (0.99, 0.97),
    ("cubicle", "dynamic"): (0.99, 0.95),
    ("meeting", "dynamic"): (0.99, 0.95),
    ("office", "dynamic"): (0.99, 0.95),
    ("dallas-q3", "dynamic"): (0.97, 0.90),
}
CITY_GOAL = (0.99, 0.93)
#: How much SPL radio must add over no radio at all, on every twin.
RADIO_MARGIN = 0.15


def goal(scene: str, variant: str) -> tuple[float, float]:
    return GOALS.get((scene, variant), CITY_GOAL)


def twins(scene: str) -> list:
    out = []
    for variant in ("blueprint", "dynamic"):
        try:
            out.append(load_dataset(f"{scene}/{variant}"))
        except DatasetNotFoundError as e:
            print(f"skipping {scene}/{variant}: {e.message}", flush=True)
    return out


def localisation_error(agent: RadioFilterAgent, ds, pairs: np.ndarray, noise: str, seed: int, steps: int) -> list:
    """Mean distance (m) between the filter's most likely cell and the true one at each of the first ``steps``
    decisions, over the episodes still running (NaN once none is)."""
    n = len(pairs)
    env = agent.env_for(ds, n, noise=noise, seed=seed, reward="paper")
    env.reset_where(torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1])
    xy = agent.positions
    running = torch.ones(n, dtype=torch.bool)
    out = []
    for _ in range(steps):
        action = agent.act(env.observe())
        gap = (xy[agent.log_belief.argmax(1)] - xy[env.cell]).norm(dim=1)
        out.append(float(gap[running].mean()) if bool(running.any()) else float("nan"))
        _, _, terminated, truncated, _ = env.step(action)
        running &= ~(terminated | truncated)
    return out


def run(args) -> dict:
    rows, tracks = [], []
    torch.set_num_threads(1)
    for scene in args.scenes:
        found = twins(scene)
        if not found:
            continue
        blueprint = found[0]
        agents = {s: RadioFilterAgent(blueprint, FilterConfig(scene=scene, sensing=s)) for s in args.sensings}
        learnt = Path(args.runs) / scene / "dqn" / "model.pt" if args.runs else dqn_checkpoint(scene)
        privileged = load_policy(learnt) if learnt.exists() else None
        for ds, seed in [(ds, seed) for ds in found for seed in args.seeds]:
            variant = ds.name.split("/")[1]
            pairs = sample_eval_pairs(ds, args.pairs, seed)
            for noise in args.noises:
                cases = [(f"radio filter ({s})", s, a) for s, a in agents.items()]
                if privileged is not None:
                    cases.append(("privileged DQN", "privileged", privileged))
                for label, sensing, agent in cases:
                    t0 = time.perf_counter()
                    m, _ = evaluate(agent, ds, pairs=args.pairs, seed=seed, noise=noise, latency=args.latency)
                    row = {"scene": scene, "twin": variant, "agent": label, "sensing": sensing, "noise": noise}
                    row["seed"] = seed
                    rows.append({**row, **m.to_dict(), "wall_s": time.perf_counter() - t0})
                    print(
                        f"{ds.name:32s} {label:34s} seed {seed} noise {noise:9s} success {m.success_rate:.3f} "
                        f"SPL {m.spl:.3f} steps {m.steps:.1f} ({time.perf_counter() - t0:.0f} s)",
                        flush=True,
                    )
                for sensing in [s for s in ("radio", "rssi", "no-radio") if s in agents and seed == args.seeds[0]]:
                    k = min(args.track_pairs, len(pairs))
                    err = localisation_error(agents[sensing], ds, pairs[:k], noise, seed, args.track_steps)
                    tracks.append({"scene": scene, "twin": variant, "sensing": sensing, "noise": noise, "error_m": err})
    return {"rows": rows, "localisation": tracks}


def spl(rows, scene, twin, sensing, noise):
    """The rows of one case averaged over their seeds (``seeds``: how many; ``spl_min``, ``success_min``: the worst
    seed's), or None."""
    found = [r for r in rows if (r["scene"], r["twin"], r["sensing"], r["noise"]) == (scene, twin, sensing, noise)]
    if not found:
        return None
    out = dict(found[0])
    for key in ("success_rate", "spl"):
        vals = [r[key] for r in found]
        out[key], out[key.split("_")[0] + "_min"] = float(np.mean(vals)), float(np.min(vals))
    out["seeds"] = len(found)
    return out


def markdown(report: dict) -> str:
    rows = report["rows"]
    noises = list(dict.fromkeys(r["noise"] for r in rows))
    lines = []
    for scene, twin in dict.fromkeys((r["scene"], r["twin"]) for r in rows):
        lines += [f"### {scene}/{twin}", "", "| sensing | " + " | ".join(f"{n}: success / SPL" for n in noises) + " |"]
        lines.append("|---|" + "---|" * len(noises))
        for sensing in dict.fromkeys(r["sensing"] for r in rows if r["scene"] == scene):
            cells = []
            for noise in noises:
                r = spl(rows, scene, twin, sensing, noise)
                cells.append("-" if r is None else f"{r['success_rate']:.3f} / {r['spl']:.3f}" + seeds_note(r))
            lines.append(f"| {sensing} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += verdicts(rows)
    return "\n".join(lines) + "\n"


def seeds_note(r) -> str:
    """For a case run over several seeds: how many, and the worst seed's success and SPL."""
    if r.get("seeds", 1) < 2:
        return ""
    return f" ({r['seeds']} seeds; worst {r['success_min']:.3f} / {r['spl_min']:.3f})"


def verdicts(rows) -> list[str]:
    """The default agent (radio, realistic noise) against its goal on each twin, and radio against no radio."""
    out = ["### The default agent against its goals (radio, realistic noise)", ""]
    out += [
        "| twin | success / SPL | goal | met | SPL without any radio | radio adds | decision p50 / p99 (ms) |",
        "|---|---|---|---|---|---|---|",
    ]
    for scene, twin in dict.fromkeys((r["scene"], r["twin"]) for r in rows):
        r, bare = spl(rows, scene, twin, "radio", "realistic"), spl(rows, scene, twin, "no-radio", "realistic")
        if r is None:
            continue
        g = goal(scene, twin)
        met = r.get("success_min", r["success_rate"]) >= g[0] and r.get("spl_min", r["spl"]) >= g[1]
        gap = "-" if bare is None else f"{r['spl'] - bare['spl']:+.3f}"
        worst = r.get("success_min", r["success_rate"]), r.get("spl_min", r["spl"])
        miss = "yes" if met else f"no: success {worst[0] - g[0]:+.3f}, SPL {worst[1] - g[1]:+.3f}"
        lat = "-" if r.get("latency_ms") is None else f"{r['latency_ms']:.2f} / {r['latency_p99_ms']:.2f}"
        out.append(
            f"| {scene}/{twin} | {r['success_rate']:.3f} / {r['spl']:.3f}{seeds_note(r)} | {g[0]} / {g[1]} | {miss} | "
            f"{'-' if bare is None else format(bare['spl'], '.3f')} | {gap} | {lat} |"
        )
    return out + [""]


def plots(report: dict, out: Path) -> list[Path]:
    rows, tracks = report["rows"], report["localisation"]
    twins_ = list(dict.fromkeys((r["scene"], r["twin"]) for r in rows))
    sensings = list(dict.fromkeys(r["sensing"] for r in rows))
    noises = list(dict.fromkeys(r["noise"] for r in rows))
    cols = min(2, len(twins_))
    fig, axes = plt.subplots(-(-len(twins_) // cols), cols, figsize=(7 * cols, 2.6 * -(-len(twins_) // cols)))
    axes = np.atleast_2d(axes)
    width = 0.8 / max(1, len(noises))
    for ax in axes.ravel()[len(twins_) :]:
        ax.axis("off")
    for ax, (scene, twin) in zip(axes.ravel(), twins_):
        for j, noise in enumerate(noises):
            vals = [(spl(rows, scene, twin, s, noise) or {}).get("spl", np.nan) for s in sensings]
            ax.bar(np.arange(len(sensings)) + j * width, vals, width, label=f"noise {noise}")
        ax.set_xticks(np.arange(len(sensings)) + width * (len(noises) - 1) / 2, sensings, fontsize=8)
        ax.set_ylim(0, 1.05)
        ax.set_ylabel("SPL")
        ax.set_title(f"{scene}/{twin}", fontsize=9)
    axes[0, 0].legend(fontsize=7, ncol=len(noises))
    fig.tight_layout()
    bars = out.with_suffix(".png")
    _save(fig, bars)
    cols = min(4, len(twins_))
    rows_ = -(-len(twins_) // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(3.6 * cols, 2.8 * rows_), squeeze=False)
    colour = {"radio": "tab:blue", "rssi": "tab:orange", "no-radio": "tab:grey"}
    style = {"none": ":", "realistic": "-", "2x": "--"}
    for ax, (scene, twin) in zip(axes.ravel(), twins_):
        for t in tracks:
            if (t["scene"], t["twin"]) == (scene, twin):
                ax.plot(
                    t["error_m"],
                    style.get(t["noise"], "-"),
                    color=colour.get(t["sensing"]),
                    label=f"{t['sensing']}, noise {t['noise']}",
                )
        ax.set_title(f"{scene}/{twin}", fontsize=9)
        ax.set_xlabel("step", fontsize=8)
        ax.set_ylabel("mean error (m)", fontsize=8)
    for ax in axes.ravel()[len(twins_) :]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=6)
    fig.suptitle("distance from the filter's most likely cell to the true one, along the episode", fontsize=10)
    fig.tight_layout()
    loc = out.with_name(out.name + "_localisation.png")
    _save(fig, loc)
    return [bars, loc]


def page(report: dict, path: Path, images: list[Path], source: Path) -> None:
    """The docs' results page, generated from the report (a re-run rewrites it). The tables sit in a block marked
    with ``source`` (the report's JSON), so ``make results-pages`` re-renders them from that JSON too."""
    path.parent.mkdir(parents=True, exist_ok=True)
    img_dir = path.parent / "img"
    img_dir.mkdir(exist_ok=True)
    links = []
    for img in images:
        target = img_dir / img.name
        target.write_bytes(img.read_bytes())
        links.append(f"![{img.stem}](img/{img.name})")
    text = [
        "# Results: what the radio contributes",
        "",
        "Generated by `bench/bench_radio.py` from its JSON; do not edit by hand. Command:",
        "",
        f"```bash\n{report['command']}\n```",
        "",
        f"Run on {report['machine_line']}, recorded {report['date']}; {report['pairs']} seeded start/target pairs per "
        "twin and seed (2024 unless the table says more), SPL from the true start on the twin navigated; each row is "
        "the default agent (the radio filter) observing with that sensing. What each sensing observes: "
        "[Sensing](../sensing.md).",
        "",
        f"<!-- results: bench-radio {source} -->",
        "",
        markdown(report).rstrip("\n"),
        "",
        "<!-- end results -->",
        "",
        *links,
        "",
    ]
    write_atomic(path, "\n".join(text))


def merge(args) -> int:
    """One report (JSON, Markdown, PNG and page) from the reports of several runs, in the order given."""
    parts = [json.loads(Path(p).read_text()) for p in args.merge]
    dates = [d for p in parts for d in p["date"].split(" to ")]  # runs of several days: their range
    report = {
        "rows": [r for p in parts for r in p["rows"]],
        "localisation": [t for p in parts for t in p["localisation"]],
        "command": "\n".join(p["command"] for p in parts),
        "machine": parts[0]["machine"],
        "machine_line": parts[0]["machine_line"],
        "date": " to ".join(sorted({min(dates), max(dates)})),
        "pairs": parts[0]["pairs"],
        "wall_s": sum(p["wall_s"] for p in parts),
    }
    return write(report, args)


def write(report: dict, args) -> int:
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out.with_suffix(".json"), json.dumps(report, indent=1) + "\n")
    md = markdown(report)
    write_atomic(out.with_suffix(".md"), md)
    images = plots(report, out)
    if args.page:
        page(report, Path(args.page), images, out.with_suffix(".json"))
    print(md, end="")
    print(f"results: {out.with_suffix('.json')}, {out.with_suffix('.md')}, " + ", ".join(map(str, images)))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), help="twins (their blueprint and dynamic variants)")
    ap.add_argument("--sensings", nargs="+", default=list(HONEST), choices=list(HONEST) + ["radio-no-proximity"])
    ap.add_argument("--noises", nargs="+", default=list(NOISES), choices=list(NOISES))
    ap.add_argument("--pairs", type=int, default=500, help="seeded start/target pairs per twin")
    ap.add_argument("--seeds", type=int, nargs="+", default=[2024], help="seeds of the pairs and the receiver noise")
    ap.add_argument("--track-steps", type=int, default=40, help="steps along which the localisation error is kept")
    ap.add_argument("--track-pairs", type=int, default=200, help="episodes whose localisation error is tracked")
    ap.add_argument("--runs", default="", help="folder of trained runs (<runs>/<scene>/dqn/model.pt; default runs/)")
    ap.add_argument("--no-latency", dest="latency", action="store_false", help="skip the decision-time figures")
    ap.add_argument("--out", default="results/bench_radio", help="output stem (.json, .md, .png)")
    ap.add_argument("--page", default="", help="also write the docs' results page here (e.g. docs/results/radio.md)")
    ap.add_argument("--merge", nargs="+", default=[], help="only merge these reports (.json of earlier runs) into one")
    args = ap.parse_args(argv)
    if args.merge:
        return merge(args)
    if args.pairs < 1 or args.track_steps < 1 or args.track_pairs < 1:
        ap.error("--pairs, --track-steps and --track-pairs must be >= 1")
    t0 = time.perf_counter()
    report = run(args)
    if not report["rows"]:
        print("error: none of the scenes is built; make dataset SCENE=<scene> first", file=sys.stderr)
        return 2
    host = machine()
    report.update(
        command="python bench/bench_radio.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        machine=host,
        machine_line=describe(host),
        date=time.strftime("%Y-%m-%d"),
        pairs=args.pairs,
        wall_s=time.perf_counter() - t0,
    )
    return write(report, args)


if __name__ == "__main__":
    sys.exit(main())
