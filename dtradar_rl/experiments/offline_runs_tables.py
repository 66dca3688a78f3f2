"""The offline results page's tables of single offline runs (``python -m dtradar_rl offline`` / ``make offline``, each
into its own ``--out``): one setting changed at a time, the updates' precision, the learning rate and updates of the
first budget (docs/results/offline.md). Pure functions of the ``results.json`` objects those runs write
(:func:`dtradar_rl.offline.trainer.train_offline`: ``config`` holds the run's settings and what they resolved to,
``results`` its evaluation rows), in the table's order; tools/renderers/offline.py registers them.

A score is the run's normalised score (0 random moves, 100 the shortest-path expert), unshielded, on each twin.
"""

from __future__ import annotations

import re
from typing import Any

from dtradar_rl.experiments.offline_bench_config import NAMES

Result = dict[str, Any]
#: The algorithms as the page's tables name them: d3rlpy's names without ``Discrete``.
SHORT = {a: n.removeprefix("Discrete") for a, n in NAMES.items()}
#: The settings a row's label names, in its order: what each reads as.
SETTINGS = ("batch_size", "hidden", "lr", "target_update_interval", "gamma", "transitions", "precision", "n_steps")


def _thousands(n: float) -> str:
    return f"{n:,.0f}".replace(",", " ")


def _count(n: int) -> str:
    """``100 K``, ``1 M``: a count of logged steps."""
    return f"{n / 1e6:g} M" if n >= 1_000_000 else f"{n / 1e3:g} K"


def _lr(x: float) -> str:
    return re.sub(r"e([+-])0*(\d)", r"e\1\2", f"{x:.0e}").replace("e+", "e")


def config(result: Result) -> dict[str, Any]:
    """The run's settings (``OfflineConfig``)."""
    return result["config"]["config"]


def score(result: Result, variant: str) -> float | None:
    """The run's unshielded normalised score on the twin ``variant``."""
    return next(
        (
            r.get("normalized")
            for r in result["results"]
            if r["dataset"].split("/")[-1] == variant and not r.get("shield")
        ),
        None,
    )


def _scores(result: Result) -> str:
    xs = [score(result, v) for v in ("blueprint", "dynamic")]
    return " / ".join("-" if x is None else f"{x:.1f}" for x in xs)


def samples(result: Result) -> str:
    """The samples a run drew, updates × batch (the batch its setting resolved to), in millions."""
    stats = result["config"].get("stats") or {}
    cfg = config(result)
    n = stats.get("n_steps", cfg["n_steps"]) * (stats.get("batch_size") or cfg["batch_size"])
    return f"{n / 1e6:.1f} M"


def _setting(key: str, value: Any, full: bool) -> str:
    """One setting as a label says it (``full``: the default row's form)."""
    if key == "batch_size":
        return f"batch {_thousands(value)}"
    if key == "hidden":
        return "hidden " + " × ".join(map(str, value))
    if key == "lr":
        return f"lr {_lr(value)}"
    if key == "target_update_interval":
        return f"target sync {_thousands(value)}" if full else f"target sync every {_thousands(value)} updates"
    if key == "gamma":
        return f"γ {value:g}"
    if key == "transitions":
        return f"{_count(value)} logged steps"
    if key == "n_steps":
        return f"{_thousands(value)} updates"
    return f"{key.replace('_', ' ')} {value}"


def setting_label(result: Result, default: Result) -> str:
    """What sets the run apart from ``default`` (its settings, the first row's), or the default row's own label."""
    cfg, ref = config(result), config(default)
    changed = [_setting(k, cfg[k], False) for k in SETTINGS if k in cfg and cfg[k] != ref.get(k)]
    if changed:
        return ", ".join(changed)
    shown = ("batch_size", "hidden", "lr", "gamma", "target_update_interval", "transitions")
    return "default: " + ", ".join(_setting(k, cfg[k], True) for k in shown if k in cfg)


def precision_setting(result: Result) -> str:
    """``bf16, batch 512``: the precision and batch the run's updates resolved to."""
    stats, cfg = result["config"].get("stats") or {}, config(result)
    precision, batch = stats.get("precision", cfg.get("precision")), stats.get("batch_size") or cfg["batch_size"]
    return f"{precision}, batch {_thousands(batch)}"


def _row(cells: list[str]) -> str:
    """A table row; an empty cell is written ``| |``."""
    return "|" + "".join(f" {c} |" if c else " |" for c in cells)


def _by_setting(results: list[Result], label) -> tuple[list[str], dict[str, dict[str, Result]]]:
    """The algorithms (in order) and ``{label: {algorithm: run}}`` (rows in order)."""
    algos = list(dict.fromkeys(config(r)["algorithm"] for r in results))
    rows: dict[str, dict[str, Result]] = {}
    for r in results:
        rows.setdefault(label(r), {})[config(r)["algorithm"]] = r
    return algos, rows


def _settings_lines(head: list[str], algos: list[str], rows: dict[str, dict[str, Result]]) -> str:
    head = head + [x for a in algos for x in (SHORT.get(a, a), "train (s)")]
    lines = [_row(head), "|" + "---|" * len(head)]
    for label, runs in rows.items():
        cells = [label, samples(next(iter(runs.values())))]
        for a in algos:
            r = runs.get(a)
            if r is None:
                cells += ["", ""]
                continue
            train_s = (r["config"].get("stats") or {}).get("train_s")  # absent: not recorded (the page leaves it blank)
            cells += [_scores(r), "" if train_s is None else f"{train_s:.1f}"]
        lines.append(_row(cells))
    return "\n".join(lines) + "\n"


def settings_table(results: list[Result]) -> str:
    """Runs that each change one setting (or a few) from the first, a row per setting: the samples drawn, and per
    algorithm the score on both twins and the training seconds (blank where that algorithm did not run)."""
    algos, rows = _by_setting(results, lambda r: setting_label(r, results[0]))
    return _settings_lines(["setting (one change from the default)", "samples drawn (updates × batch)"], algos, rows)


def precision_table(results: list[Result]) -> str:
    """Runs that differ in their updates' precision and batch, a row per (precision, batch) they resolved to."""
    algos, rows = _by_setting(results, precision_setting)
    return _settings_lines(["setting", "samples"], algos, rows)


def budget_table(results: list[Result]) -> str:
    """The blueprint score of runs that differ in learning rate and updates: a row per (dataset family, algorithm) in
    the order the runs come, a column per (updates, learning rate), fewer updates first (blank: not run)."""
    rows: dict[tuple[str, str], dict[tuple[int, float], Result]] = {}
    for r in results:
        cfg = config(r)
        family = (cfg.get("logged") or cfg.get("behaviour", "")).split("/")[-1]
        rows.setdefault((family, cfg["algorithm"]), {})[cfg["n_steps"], cfg["lr"]] = r
    cols = sorted({k for runs in rows.values() for k in runs})
    head = ["data", "algorithm"] + [
        f"lr {_lr(lr)}, {_thousands(n / 1e3)} K" + (" updates" if i == 0 else "") for i, (n, lr) in enumerate(cols)
    ]
    lines = [_row(head), "|" + "---|" * len(head)]
    for (family, algo), runs in rows.items():
        cells = [
            "" if k not in runs or score(runs[k], "blueprint") is None else f"{score(runs[k], 'blueprint'):.1f}"
            for k in cols
        ]
        lines.append(_row([family, SHORT.get(algo, algo), *cells]))
    return "\n".join(lines) + "\n"


__all__ = ["SHORT", "budget_table", "precision_setting", "precision_table", "score", "setting_label", "settings_table"]
