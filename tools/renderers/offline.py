"""Renderers of docs/results/offline.md's tables that set several runs side by side (the offline benchmark's
``bench.json`` of several settings, single ``offline`` runs' ``results.json``) or read one benchmark's JSON another
way: each calls the package's or the benchmark script's own function (dtradar_rl.experiments.offline_report_tables,
dtradar_rl.experiments.offline_runs_tables, bench/bench_relabel.py), never a copy of it."""

from __future__ import annotations

from renderers.base import Renderer, bench, module

TABLES = "dtradar_rl.experiments.offline_report_tables"
RUNS = "dtradar_rl.experiments.offline_runs_tables"
BENCH = "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)"
SEVERAL = "python -m dtradar_rl offline-bench --out <each JSON's folder> (with the options the page names for each)"
OFFLINE = "python -m dtradar_rl offline --out <each JSON's folder> (with the settings the page names for each)"


def _tables(func: str, **kw):
    return lambda d, o: module(TABLES, func)(d, **kw)


def _runs(func: str):
    return lambda d, o: module(RUNS, func)(d)


#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "offline-logged": Renderer(_tables("logged_table"), BENCH),
    "offline-defaults": Renderer(
        lambda d, o: module(TABLES, "defaults_table")(d, lost=o["lost"] == "yes"),
        SEVERAL,
        flags=("lost",),
        several=True,
    ),
    "offline-relabelling": Renderer(_tables("relabelling_table"), SEVERAL, several=True),
    "offline-senses": Renderer(_tables("senses_table"), SEVERAL, several=True),
    "offline-ogbench": Renderer(_tables("ogbench_table"), SEVERAL, several=True),
    "offline-best-learners": Renderer(_tables("best_learners_table"), SEVERAL, several=True),
    "offline-updates": Renderer(_tables("updates_table"), SEVERAL, several=True),
    "offline-precision": Renderer(_tables("precision_table"), SEVERAL, several=True),
    "offline-scores-online": Renderer(
        lambda d, o: module(TABLES, "scores_with_online")(d, o["variant"]), BENCH, ("variant",)
    ),
    "offline-relabel": Renderer(
        lambda d, o: bench("bench_relabel.py", "table")(d, o["scene"], bold=o["bold"] == "yes"),
        "python bench/bench_relabel.py --out {dir} (with the scenes, families, algorithms and mixes the page names)",
        ("scene",),
        ("bold",),
    ),
    "offline-one-change": Renderer(_runs("settings_table"), OFFLINE, several=True),
    "offline-run-precision": Renderer(_runs("precision_table"), OFFLINE, several=True),
    "offline-budget": Renderer(_runs("budget_table"), OFFLINE, several=True),
}
