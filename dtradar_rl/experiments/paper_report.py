"""``report.md`` of ``make paper``: the paper's tables and figures, ours beside the paper's numbers.

A pure function of the :class:`~dtradar_rl.experiments.paper.Report` (no I/O), so the wording of the report is tested
without training anything.
"""

from __future__ import annotations

import re
from typing import Any

from dtradar_rl.experiments.paper_reach import HORIZON
from dtradar_rl.experiments.paper_seeds import GOAL_FRACTION

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


def _spread(d: dict[str, Any]) -> str:
    """median [min-max] (n of N) of a per-seed value that some seeds may lack."""
    total = len(d["values"])
    if not d["n"]:
        return f"none of {total}"
    rng = f"{d['min']:g}" if d["min"] == d["max"] else f"{d['min']:g}–{d['max']:g}"
    return f"{d['median']:g} [{rng}]" + (f" ({d['n']} of {total})" if d["n"] < total else "")


def _training(report) -> str:
    rows = []
    for t in report.training:
        p, pair = t["paper"], t["pair"]
        g = t["greedy_reached"]
        n = t["n_seeds"]
        verdict = f"{t['reproduced']} of {n}" + (
            " — **met**" if t["goal_met"] else f" — **not met** (goal {t['needed']})"
        )
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
                verdict,
                f"{g.get('blueprint', 0)} of {n} / " + (f"{g['dynamic']} of {n}" if "dynamic" in g else "-"),
                _spread(t["min_steps"]),
                _spread(t["min_episode"]),
                _spread(t["first_within_10pct"]),
                f"{p['min_steps']} ({p['episode']})" if p else "-",
            ]
        )
    return _table(
        [
            "scene",
            "paper pair (paper's frame)",
            "our cells (ix, iy)",
            "shortest (BFS)",
            "seeds reproducing the pair",
            "greedy reaches: blueprint / dynamic",
            "min steps: median [range]",
            "at episode",
            "first episode within 10 %",
            "paper: min steps (episode)",
        ],
        rows,
    )


def _p(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x:.2f}" if x >= 0.01 or x == 0 else f"{x:.1e}"


def _steps(q: int | None) -> str:
    return _n(q) if q is not None else f"> {HORIZON:,}"


def _reach(report) -> str:
    """How far, and why (:mod:`~dtradar_rl.experiments.paper_reach`): one row per scene."""
    rows = []
    for t in report.training:
        r = t.get("reach")
        if not r:
            continue
        o, u, e = r["optimum"], r["chains"]["uniform"], r["chains"]["eps_optimal"]
        cap, cap10 = (str(c) for c in r["caps"])
        walk = f"reaches it in {o['steps']}" if o["reached"] else f"**settles {o['settles_at']} cells from it**"
        misses = [x for x in t["runs"] if not x["greedy"]["blueprint"]["reached"]]
        rows.append(
            [
                t["scene"],
                r["shortest"],
                cap,
                walk,
                f"{_p(u['within'][cap])} / {_p(e['within'][cap])}",
                _p(u["within"][cap10]),
                f"{_steps(u['quantiles']['0.5'])} / {_steps(u['quantiles']['0.99'])}",
                f"{t['episodes_reached']} of {t['episodes']}",
                ", ".join(str(x["greedy"]["blueprint"]["closest"]) for x in misses) or "- (all reach it)",
                ", ".join(_p(x["learned"]["within"][cap]) for x in t["runs"] if "learned" in x) or "-",
            ]
        )
    return _table(
        [
            "scene",
            "shortest",
            "safety cap (10 × shortest)",
            "the paper's MDP solved (γ 0.9): its greedy walk from the start",
            "P(an episode hits the target within the safety cap): untrained / ε-greedy optimum",
            "within 10 × the safety cap: untrained",
            "untrained: steps for 50 % / 99 % of episodes to hit it",
            "training episodes that reached it (all seeds)",
            "greedy misses: nearest approach (cells from the target)",
            "each seed's trained agent, ε-greedy (ε 0.1): P(hit within the safety cap)",
        ],
        rows,
    )


def _cap(cfg: dict[str, Any]) -> str:
    cap = cfg.get("max_steps") or 0
    budget = cfg.get("total_env_steps") or 0
    said = f"episodes capped at {cap:,} steps" if cap else "safety cap 10 × the shortest path"
    return said + (f", at most {budget:,} environment steps per run" if budget else "")


def _greedy(x: dict[str, Any] | None) -> str:
    if x is None:
        return "-"
    return f"{x['steps']}, reached" if x["reached"] else f"**not reached** ({x['collisions']} collisions)"


def _per_seed(report) -> str:
    rows = []
    for t in report.training:
        for r in t["runs"]:
            g = r["greedy"]

            rows.append(
                [
                    t["scene"],
                    r["seed"],
                    "-" if r["min_steps"] is None else f"{r['min_steps']} ({r['min_episode']})",
                    _n(r["first_within_10pct"]),
                    _greedy(g.get("blueprint")),
                    _greedy(g.get("dynamic")),
                    r["episodes"],
                    _n(r["env_steps"]),
                    "reused" if r["reused"] else f"{r['wall_s']:.0f} s",
                    r["threads"],
                ]
            )
    return _table(
        [
            "scene",
            "seed",
            "min steps (episode)",
            "first within 10 %",
            "greedy: blueprint",
            "greedy: dynamic",
            "episodes",
            "env steps",
            "training time",
            "torch threads",
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
            f"{i['reached']} of {len(i['seeds'])}",
            ", ".join(str(x["steps"]) if x["reached"] else f"~~{x['steps']}~~" for x in i["seeds"]),
            ", ".join(str(x["collisions"]) for x in i["seeds"]),
        ]
        for i in report.inference
    ]
    return _table(
        [
            "scene",
            "twin",
            "pair",
            "shortest",
            "seeds reaching it",
            "steps per seed (struck: not reached)",
            "collisions",
        ],
        rows,
    )


def _table_vii(report) -> str:
    rows, steps, wall, runs = [], 0, 0.0, 0
    for t in report.training:
        rate = t["env_steps"] / t["wall_s"] if t["wall_s"] else None
        rows.append(
            [
                t["scene"],
                t["n_seeds"],
                t["episodes"],
                _n(t["env_steps"]),
                _n(t["updates"]),
                f"{t['wall_s']:.1f} s ({t['wall_s'] / t['n_seeds']:.0f} s per run)",
                _n(rate, "{:,.0f}"),
                f"{PAPER_STEPS / rate / 60:.1f} min" if rate else "-",
                f"{t['reused']} reused" if t["reused"] else "trained now",
            ]
        )
        steps += t["env_steps"]
        wall += t["wall_s"]
        runs += t["n_seeds"]
    if rows:
        rate = steps / wall if wall else None
        rows.append(
            [
                "**all**",
                runs,
                sum(t["episodes"] for t in report.training),
                f"**{steps:,}**",
                _n(sum(t["updates"] for t in report.training)),
                f"**{wall / 60:.1f} min** of training",
                _n(rate, "{:,.0f}"),
                f"**{PAPER_STEPS / rate / 60:.1f} min**" if rate else "-",
                "",
            ]
        )
        rows.append(
            [
                "paper (Table VII)",
                1,
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
            "runs (seeds)",
            "episodes",
            "env steps",
            "updates",
            "training time, summed over runs",
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
        f"#### {c['group']}\n\nGoal-conditioned agents (`{c['preset']}` preset, one seed ({c.get('seed', 0)}), "
        f"{c['steps']:,} environment steps each; training time {times}), {c['pairs']} seeded random pairs per cell; "
        "success / SPL "
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
            "## Table VI: training pairs, minimum steps and the episode they were reached, over seeds\n\n"
            "The paper's agent (`--preset paper`: 10 inputs, 5 × 256 ReLU, Huber loss, γ = 0.9, ε = 0.1, "
            "the paper's reward), one pair per run, episodes until the target ("
            + _cap(report.config)
            + "), trained once per seed. *min steps* is the fewest decisions (collisions included) of a "
            "training episode that reached the target, with ε-greedy exploration on. A seed *reproduces the pair* "
            "when its training found a path within 10 % of the breadth-first optimum and its greedy policy reaches "
            f"the target on the blueprint; the goal is met when at least {round(100 * GOAL_FRACTION)} % of the seeds "
            "do (4 of 5). The paper reports one run.\n\n" + _training(report) + "\nEach seed:\n\n" + _per_seed(report)
        )
        out.append(
            "\n### How far, and why (exact, from each pair's MDP)\n\n"
            "No seed in these: the pair's target solved under the paper's reward at γ = 0.9 and its greedy policy "
            "followed from the start (a learner that fits the paper's MDP perfectly acts so), and the exact "
            "probability that one episode hits the target within the safety cap, for an untrained agent (a uniform "
            "random walk) and for ε-greedy (ε = 0.1) on that optimum, from the absorbing Markov chain of each, and the "
            "steps an untrained episode takes to hit it: a cap that binds in under 1 % of untrained episodes must "
            "exceed the 99 % figure. The last column is each trained agent's own chain (its greedy move on every "
            "cell, with the training's ε = 0.1). "
            "Beside them what the seeds did.\n\n" + _reach(report)
        )
        out.append(
            "\n## Training curves (paper Figs. 9, 11-16, 18-21)\n\n"
            "Steps and collisions per episode, each seed a thin line and the median over seeds bold; right, the "
            "fewest steps each seed has found so far.\n\n"
            + "\n".join(
                f"- `{t['scene']}/blueprint`:\n\n  ![{t['scene']}](figures/{t['png']})" for t in report.training
            )
            + "\n"
        )
        out.append(
            "\n## Inference paths on the blueprint and dynamic twins (paper Figs. 10, 22-24)\n\n"
            "Each seed's trained agent, greedy, on its pair, all seeds' paths in one picture (on a dynamic twin an "
            "end that became blocked is snapped to the nearest free cell).\n\n"
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
