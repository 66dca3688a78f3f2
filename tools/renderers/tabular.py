"""Renderers of docs/results/tabular.md: ``make solve``'s solve.json of several scenes (its own twins_table), ``make
bench-tabular``'s JSON (bench/bench_tabular_report.py), and two tables of the offline benchmark's tabular rows laid
out here from its bench.json (the page sets blueprint / dynamic in one cell, and several runs side by side; the
offline report's own tables are one twin each): the return-based score, and the tables with senses."""

from __future__ import annotations

from typing import Any

from renderers.base import Renderer, bench, module

_REPORT = "dtradar_rl.experiments.offline_report"


def _pair(result: dict[str, Any], beh: str, column: str, key: str) -> str:
    """``98.8 / 83.6``: a tabular column's score on each twin of the benchmark, ``-`` where it has none."""
    score, num = module(_REPORT, "tabular_score"), module(_REPORT, "_num")
    return " / ".join(num(score(result, beh, column, v, key)) for v in result["config"]["variants"])


def _columns(result: dict[str, Any], key: str, ceiling: bool) -> list[str]:
    """The tabular columns of ``result`` that hold a score (a benchmark of before the tables with senses has none
    of theirs)."""
    score = module(_REPORT, "tabular_score")
    return [
        c
        for c in module(_REPORT, "TABULAR_COLUMNS")
        if (ceiling or c != "ceiling")
        and any(
            score(result, beh, c, v, key) is not None
            for beh in result.get("tabular") or {}
            for v in result["config"]["variants"]
        )
    ]


def returns_table(result: dict[str, Any], options: dict[str, str]) -> str:
    """The return-based normalised score of the ceiling and the tables, blueprint / dynamic, a row per dataset."""
    names = module(_REPORT, "TABULAR_COLUMNS")
    cols = _columns(result, "return_normalized", ceiling=True)
    lines = ["| dataset | " + " | ".join(names[c] for c in cols) + " |", "|---" * (1 + len(cols)) + "|"]
    for beh in result.get("tabular") or {}:
        lines.append(f"| {beh} | " + " | ".join(_pair(result, beh, c, "return_normalized") for c in cols) + " |")
    return "\n".join(lines) + "\n"


def _best_deep(result: dict[str, Any], beh: str) -> str:
    """The best d3rlpy algorithm's mean normalised score on each twin (each twin's own best)."""
    cells = []
    for v in result["config"]["variants"]:
        means = [
            e[v]["normalized"]["mean"]
            for e in result["summary"]
            if e["behaviour"] == beh and ((e.get(v) or {}).get("normalized") or {}).get("mean") is not None
        ]
        cells.append(f"{max(means):.1f}" if means else "-")
    return " / ".join(cells)


def senses_table(data: list[dict[str, Any]], options: dict[str, str]) -> str:
    """The tables (with senses in bold) of each scene's tabular run beside the best deep learner of its deep run:
    the JSONs in pairs, (tabular run, deep run) per scene, a row per (scene, dataset); normalised score,
    blueprint / dynamic."""
    names = module(_REPORT, "TABULAR_COLUMNS")
    pairs = list(zip(data[::2], data[1::2], strict=True))
    cols = _columns(pairs[0][0], "normalized", ceiling=False)
    head = [f"**{names[c]}**" if c.endswith("-senses") else names[c] for c in cols]
    lines = [
        "| dataset | " + " | ".join(head) + " | best deep learner (one seed, above) |",
        "|---" * (2 + len(cols)) + "|",
    ]
    for tab, deep in pairs:
        scene = tab["config"]["scene"]
        for beh in tab.get("tabular") or {}:
            cells = [_pair(tab, beh, c, "normalized") for c in cols] + [_best_deep(deep, beh)]
            lines.append(f"| {scene} {beh} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _steps(options: dict[str, str]) -> list[int]:
    return [int(x) for x in options["steps"].split(",") if x]


_OFFLINE = "python -m dtradar_rl offline-bench --scene <scene> --out {dir} (with the options the page names)"

#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "tabular-solve": Renderer(
        lambda d, o: module("dtradar_rl.experiments.solve", "twins_table")(d),
        "make solve SCENE=<scene> for each scene the page names (writes results/solve/<scene>/solve.json)",
        several=True,
    ),
    "tabular-curves": Renderer(
        lambda d, o: bench("bench_tabular_report.py", "page_curves")(d, _steps(o)),
        'make bench-tabular ARGS="--out {dir} --name {name}"',
        options=("steps",),
    ),
    "tabular-learners": Renderer(
        lambda d, o: bench("bench_tabular_report.py", "page_learners")(d),
        'make bench-tabular ARGS="--out {dir} --name {name}"',
    ),
    "tabular-returns": Renderer(returns_table, _OFFLINE),
    "tabular-senses": Renderer(
        senses_table,
        _OFFLINE + "; each scene's --no-deep run, then its run with the deep learners",
        several=True,
    ),
}
