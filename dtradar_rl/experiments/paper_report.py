"""``report.md`` of ``make paper``: the paper's tables and figures, ours beside the paper's numbers.

A pure function of the :class:`~dtradar_rl.experiments.paper.Report` (no I/O), so the wording of the report is tested
without training anything.
"""

from __future__ import annotations

import re
from typing import Any

PAPER_TABLE_II = {
    "cubicle": ("42 × 18", 757),
    "meeting": ("38 × 40", 1521),
    "dallas": ("137 × 130", 456_483),
    "houston": ("507 × 473", 232_363),
}
PAPER_TABLE_V = {"dallas-q3": ("-", 123_825), "houston-q2": ("180 × 200", 61_216)}
PAPER_STEPS, PAPER_MINUTES = 600_000, 46
_QUADRANT = re.compile(r"^(.+)-q(\d)$")


def _n(v, fmt="{:,}") -> str:
    return "-" if v is None else fmt.format(v)


def _size(b) -> str:
    if b is None:
        return "- (in memory)"
    return f"{b / 1e6:.2f} MB" if b >= 1e5 else f"{b / 1e3:.1f} kB"


def _table(head: list[str], rows: list[list[Any]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _datasets(report, variant: str, paper: dict) -> str:
    rows, cities = [], {}
    for d in report.datasets:
        scene, var = d["dataset"].split("/")
        if var != variant:
            continue
        key = scene if scene in paper else None
        m = _QUADRANT.match(scene)
        if variant == "blueprint" and m:
            cities.setdefault(m.group(1), []).append(d)
        pg, pr = paper.get(key, ("-", None)) if key else ("-", None)
        rows.append(
            [
                f"`{d['dataset']}`",
                f"{d['nx']} × {d['ny']}",
                f"{d['cell_m']:g} m",
                _n(d["rows"]),
                _n(d["free"]),
                _size(d["bytes"]),
                pg,
                _n(pr),
            ]
        )
    for city, ds in cities.items():  # the paper's blueprint row of a city merges its quadrants
        pg, pr = paper.get(city, ("-", None))
        sizes = [d["bytes"] for d in ds]
        rows.append(
            [
                f"**{city}, {len(ds)} quadrant(s) merged**",
                f"{len(ds)} × {ds[0]['nx']} × {ds[0]['ny']}",
                f"{ds[0]['cell_m']:g} m",
                _n(sum(d["rows"] for d in ds)),
                _n(sum(d["free"] for d in ds)),
                _size(None if None in sizes else sum(sizes)),
                pg,
                _n(pr),
            ]
        )
    if not rows:
        return "_No dataset of this kind was built._\n"
    return _table(
        ["dataset", "grid (nx × ny)", "cell", "rows", "free cells", "size on disk", "paper grid", "paper rows"], rows
    )


def _training(report) -> str:
    rows = []
    for t in report.training:
        p = t["paper"]
        pair = t["pair"]
        ratio = f"{t['min_steps'] / pair['shortest']:.2f}" if t["min_steps"] else "-"
        ok = "yes" if t["min_steps"] and t["min_steps"] <= 1.1 * pair["shortest"] else "**no**"
        rows.append(
            [
                t["scene"],
                f"{list(p['start'])} → {list(p['target'])} ({p['frame']})" if p else "- (stand-in pair)",
                f"{tuple(pair['start'])} → {tuple(pair['target'])}"
                + (
                    f" (snapped {pair['snapped_cells'][0]:.1f}, {pair['snapped_cells'][1]:.1f} cells)"
                    if any(pair["snapped_cells"])
                    else ""
                ),
                pair["shortest"],
                _n(t["min_steps"]),
                _n(t["min_episode"]),
                ratio,
                ok,
                _n(t["first_within_10pct"]),
                _n(t.get("greedy_steps")),
                _n(p["min_steps"]) if p else "-",
                _n(p["episode"]) if p else "-",
            ]
        )
    return _table(
        [
            "scene",
            "paper pair (paper's frame)",
            "our cells (ix, iy)",
            "shortest (BFS)",
            "min steps",
            "at episode",
            "min / shortest",
            "within 10 %",
            "first episode within 10 %",
            "greedy after training",
            "paper min steps",
            "paper episode",
        ],
        rows,
    )


def _inference(report) -> str:
    rows = [
        [
            i["scene"],
            i["variant"],
            f"{tuple(i['start'])} → {tuple(i['target'])}",
            i["shortest"],
            "yes" if i["reached"] else "**no**",
            i["steps"],
            i["path_length"],
            i["collisions"],
        ]
        for i in report.inference
    ]
    return _table(["scene", "twin", "pair", "shortest", "reached", "steps", "cells travelled", "collisions"], rows)


def _table_vii(report) -> str:
    rows, steps, wall = [], 0, 0.0
    for t in report.training:
        rate = t["env_steps"] / t["wall_s"] if t["wall_s"] else None
        rows.append(
            [
                t["scene"],
                t["episodes"],
                _n(t["env_steps"]),
                _n(t["updates"]),
                f"{t['wall_s']:.1f} s",
                _n(rate, "{:,.0f}"),
                f"{PAPER_STEPS / rate / 60:.1f} min" if rate else "-",
                "reused" if t["reused"] else "trained now",
            ]
        )
        steps += t["env_steps"]
        wall += t["wall_s"]
    if rows:
        rate = steps / wall if wall else None
        rows.append(
            [
                "**all**",
                sum(t["episodes"] for t in report.training),
                f"**{steps:,}**",
                _n(sum(t["updates"] for t in report.training)),
                f"**{wall / 60:.1f} min**",
                _n(rate, "{:,.0f}"),
                f"**{PAPER_STEPS / rate / 60:.1f} min**" if rate else "-",
                "",
            ]
        )
        rows.append(
            [
                "paper (Table VII)",
                "500 indoor / 80 outdoor",
                f"{PAPER_STEPS:,}",
                "-",
                f"{PAPER_MINUTES} min",
                f"{PAPER_STEPS / PAPER_MINUTES / 60:,.0f}",
                f"{PAPER_MINUTES} min",
                "a CPU (not named further)",
            ]
        )
    return _table(
        [
            "scene",
            "episodes",
            "env steps",
            "updates",
            "training time",
            "steps/s",
            "time for 600 K steps at this rate",
            "",
        ],
        rows,
    )


def _cross(c: dict[str, Any]) -> str:
    m, s = c["matrix"], c["scenes"]
    head = ["trained on \\ evaluated on"] + s
    rows = [[r] + [f"{m['success'][i][j]:.3f} / {m['spl'][i][j]:.3f}" for j in range(len(s))] for i, r in enumerate(s)]
    own = ", ".join(f"{k}: success {v['success']:.3f}, SPL {v['spl']:.3f}" for k, v in c["own"].items())
    times = ", ".join(f"{k} {v:.0f} s" for k, v in c["train_s"].items() if v is not None)
    return (
        f"#### {c['group']}\n\nGoal-conditioned agents (`{c['preset']}` preset, {c['steps']:,} environment "
        f"steps each; training time {times}), {c['pairs']} seeded random pairs per cell; success / SPL "
        f"against the breadth-first optimum of the evaluated quadrant.\n\n"
        + _table(head, rows)
        + f"\nOn its own quadrant: {own}.\n\n![bars](figures/{c['png']['bars']})\n"
        f"![success](figures/{c['png']['heatmap_success']}) ![spl](figures/{c['png']['heatmap_spl']})\n"
    )


def shared_machine(mc: dict) -> bool:
    """Whether other jobs competed with the run: a load average above the core count (the run itself keeps at most
    one thread per core busy, so it alone reaches about the core count), or a busy machine before it started."""
    cores = mc.get("cores") or 1
    return (mc.get("load_avg_max") or 0) > cores + 0.5 or (mc.get("load_avg_start") or 0) > 0.5 * cores


def render(report) -> str:
    mc = report.machine
    machine = (
        f"{mc['cpu']}, {mc['cores']} cores"
        + (f", GPU {mc['gpu']}" if mc.get("gpu") else ", no GPU")
        + f"; torch {mc['torch']}; 1-min load average {mc['load_avg_start']} at the start, "
        f"{mc.get('load_avg_max')} at most, {mc.get('load_avg_end')} at the end"
        + (" (the machine was shared with other jobs: times are pessimistic)" if shared_machine(mc) else "")
    )
    out = [
        f"# DT-RaDaR (arXiv 2411.12284) regenerated\n\nMachine: {machine}. Whole report: "
        f"{report.wall_s / 60:.1f} min. Every number of the paper below is from its text and tables; its own "
        "grids are larger than ours for the cities, so its step counts are not comparable cell for cell.\n"
    ]
    if report.missing:
        out.append(
            "## Not built (skipped)\n\n"
            + _table(["dataset", "build it with"], [[f"`{m['dataset']}`", f"`{m['command']}`"] for m in report.missing])
        )
    out.append(
        "## Tables II and V: the datasets\n\n### Table II (blueprint twins)\n\n"
        + _datasets(report, "blueprint", PAPER_TABLE_II)
        + "\n### Table V (dynamic twins)\n\n"
        + _datasets(report, "dynamic", PAPER_TABLE_V)
        + "\nThe paper's city grid sizes and row counts disagree with each other (Table II vs. its text); "
        "ours are the quadrant grids of the scene files (4 m cells).\n"
    )
    out.append(
        "## Coverage maps (paper Figs. 5 and 7)\n\n"
        + "\n".join(
            f"- `{c['dataset']}` ({c['source']}):\n\n  ![{c['dataset']}](figures/{c['png']})" for c in report.coverage
        )
        + "\n"
    )
    if report.training:
        out.append(
            "## Table VI: training pairs, minimum steps and the episode they were reached\n\n"
            "The paper's agent (`--preset paper`: 10 inputs, 5 × 256 ReLU, Huber loss, γ = 0.9, ε = 0.1, "
            "the paper's reward), one pair per run, episodes until the target (safety cap 10 × the "
            "shortest path). *min steps* is the fewest decisions (collisions included) of a training "
            "episode that reached the target, with ε-greedy exploration on.\n\n" + _training(report)
        )
        out.append(
            "\n## Training curves (paper Figs. 9, 11-16, 18-21)\n\n"
            + "\n".join(
                f"- `{t['scene']}/blueprint`:\n\n  ![{t['scene']}](figures/{t['png']})" for t in report.training
            )
            + "\n"
        )
        out.append(
            "\n## Inference paths on the blueprint and dynamic twins (paper Figs. 10, 22-24)\n\n"
            "The trained agent, greedy, on its pair (on a dynamic twin an end that became blocked is "
            "snapped to the nearest free cell).\n\n"
            + _inference(report)
            + "\n"
            + "\n".join(
                f"- `{i['scene']}/{i['variant']}`:\n\n  ![{i['scene']} {i['variant']}](figures/{i['png']})"
                for i in report.inference
            )
            + "\n"
        )
        out.append("\n## Table VII: training time for the paper's budget\n\n" + _table_vii(report))
    if report.cross:
        out.append("\n## Cross-quadrant inference (paper Fig. 17)\n\n" + "\n".join(_cross(c) for c in report.cross))
    elif report.config.get("cross"):
        out.append(
            "\n## Cross-quadrant inference (paper Fig. 17)\n\n_Needs at least two built quadrants of a city "
            "among --scenes (or --cross-scenes)._\n"
        )
    return "\n".join(out)


__all__ = ["render"]
