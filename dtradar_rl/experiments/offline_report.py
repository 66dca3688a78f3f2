"""What the offline-RL benchmark writes besides its runs: the mean ± std over seeds, the rank correlation of FQE and the
true value, ``bench.md``, ``bench.png`` and ``bench_fqe.png``.

Pure functions of the benchmark's JSON object (:func:`dtradar_rl.experiments.offline_bench.run_bench`), so the tables
and figures are tested without training anything. The headline is the **normalised score**
(:mod:`dtradar_rl.evaluation.normalized`: 0 = uniformly random moves, 100 = the breadth-first shortest-path expert,
from the SPL on the twin's seeded evaluation pairs), one table per evaluated twin laid out like D4RL's: a row per
dataset family, a column per algorithm, the behaviour itself beside them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dtradar_rl.evaluation.evaluate import METRICS
from dtradar_rl.task.runtime import describe

#: What every run reports per evaluated twin: the normalised score first, then the raw metrics it comes from.
SCORES: tuple[str, ...] = ("normalized", *METRICS)


def aggregate(values: list[float]) -> dict[str, float]:
    """Mean and (population) standard deviation over seeds."""
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=0)), "n": int(len(v))}


def spearman(x: list[float], y: list[float]) -> float | None:
    """Spearman's rank correlation of ``x`` and ``y`` (ties get their mean rank); None with fewer than 3 points or
    a constant side."""
    from scipy.stats import spearmanr

    if len(x) < 3 or len(set(x)) < 2 or len(set(y)) < 2:
        return None
    rho = float(spearmanr(x, y).statistic)
    return None if math.isnan(rho) else rho


def summarize(
    runs: list[dict[str, Any]], behaviours: list[str], algorithms: list[str], variants: list[str]
) -> list[dict[str, Any]]:
    """One entry per (dataset, algorithm) with runs so far: every score of every twin and the FQE / true values as
    mean ± std over the seeds."""
    summary = []
    for beh in behaviours:
        for algo in algorithms:
            rs = [r for r in runs if r["behaviour"] == beh and r["algorithm"] == algo]
            if not rs:
                continue
            entry: dict[str, Any] = {
                "behaviour": beh,
                "algorithm": algo,
                "seeds": [r["seed"] for r in rs],
                "train_s": aggregate([r["train_s"] for r in rs]),
            }
            for v in variants:
                if all(v in r for r in rs):
                    entry[v] = {m: aggregate([r[v][m] for r in rs]) for m in SCORES if all(m in r[v] for r in rs)}
            for k in ("fqe", "true_value"):
                if all(k in r for r in rs):
                    entry[k] = aggregate([r[k] for r in rs])
            summary.append(entry)
    return summary


def ope_summary(runs: list[dict[str, Any]], gamma: float, fqe_steps: int) -> dict[str, Any]:
    """FQE against the true value over every agent so far: the rank correlation, overall and per dataset."""
    got = [r for r in runs if "fqe" in r and "true_value" in r]
    per = {}
    for beh in dict.fromkeys(r["behaviour"] for r in got):
        rs = [r for r in got if r["behaviour"] == beh]
        per[beh] = {"spearman": spearman([r["fqe"] for r in rs], [r["true_value"] for r in rs]), "n": len(rs)}
    return {
        "spearman": spearman([r["fqe"] for r in got], [r["true_value"] for r in got]),
        "n": len(got),
        "per_dataset": per,
        "gamma": gamma,
        "fqe_steps": fqe_steps,
        "value": "mean discounted return (logged reward) from the logged episodes' (start, target) pairs, greedy and "
        "unshielded: FQE from the logged transitions, true by rollouts on the blueprint twin",
    }


def best_per_dataset(result: dict[str, Any], variant: str) -> dict[str, dict[str, Any]]:
    """``{dataset: summary entry}``: the algorithm with the highest mean normalised score on ``variant``."""
    best: dict[str, dict[str, Any]] = {}
    for e in result["summary"]:
        m = (e.get(variant) or {}).get("normalized")
        if m is None:
            continue
        cur = best.get(e["behaviour"])
        if cur is None or m["mean"] > cur[variant]["normalized"]["mean"]:
            best[e["behaviour"]] = e
    return best


def _pm(a: dict[str, float] | None, fmt: str = "{:.3f}") -> str:
    if not a:
        return "-"
    return fmt.format(a["mean"]) + (" ± " + fmt.format(a["std"]) if a["n"] > 1 else "")


def _num(x: float | None, fmt: str = "{:.1f}") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


#: The tabular columns of the score table, in order (dtradar_rl.tabular.batch): the data ceiling, then the learners.
TABULAR_COLUMNS: dict[str, str] = {
    "ceiling": "data ceiling",
    "ce": "CE",
    "lcb": "VI-LCB",
    "spibb": "Π_b-SPIBB",
    "ce-senses": "CE + senses",
    "lcb-senses": "VI-LCB + senses",
}


#: The tabular columns with an honest sensing (dtradar_rl.experiments.offline_tabular_honest): each table followed
#: through the localisation filter; no ceiling (it is defined on the true cell).
HONEST_TABULAR_COLUMNS: dict[str, str] = {
    "ce-filter": "CE + filter",
    "lcb-filter": "VI-LCB + filter",
    "spibb-filter": "Π_b-SPIBB + filter",
}


def tabular_columns(result: dict[str, Any]) -> dict[str, str]:
    """The tabular columns of ``result``'s tables (none when it ran no tabular learner)."""
    if not result.get("tabular"):
        return {}
    honest = result["config"].get("sensing", "privileged") != "privileged"
    return HONEST_TABULAR_COLUMNS if honest else TABULAR_COLUMNS


def tabular_score(result: dict[str, Any], beh: str, column: str, variant: str, key: str = "normalized"):
    row = ((result.get("tabular") or {}).get(beh) or {}).get(column) or {}
    return (row.get(variant) or {}).get(key)


def score_table(result: dict[str, Any], variant: str) -> list[str]:
    """The quotable table of one twin: a row per dataset, the behaviour itself, the data's ceiling and the tabular
    batch learners (when the benchmark ran them), then every d3rlpy algorithm's normalised score (mean ± std over
    seeds); the best learner of each row (tabular or deep, not the ceiling) in bold."""
    algos = list(result["algorithms"])
    names = tabular_columns(result)
    tab_cols = list(names)
    best = best_per_dataset(result, variant)
    lines = [
        "| "
        + " | ".join(["dataset", "behaviour itself", *(names[c] for c in tab_cols)])
        + "".join(f" | {result['algorithms'][a]}" for a in algos)
        + " |",
        "|" + "---|" * (2 + len(tab_cols) + len(algos)),
    ]
    for beh, d in result["datasets"].items():
        own = ((d.get("eval") or {}).get(variant) or {}).get("normalized")
        deep = []
        for a in algos:
            e = next((e for e in result["summary"] if e["behaviour"] == beh and e["algorithm"] == a), None)
            m = ((e or {}).get(variant) or {}).get("normalized")
            deep.append((_pm(m, "{:.1f}"), None if m is None else m["mean"], e is not None and best.get(beh) is e))
        tab = [(c, tabular_score(result, beh, c, variant)) for c in tab_cols]
        learnt = [x for c, x in tab if c != "ceiling" and x is not None]
        top = max(learnt + [x for _, x, _ in deep if x is not None], default=None)
        best_deep = max([x for _, x, _ in deep if x is not None], default=None)
        cells = [f"**{_num(x)}**" if c != "ceiling" and x is not None and x == top else _num(x) for c, x in tab] + [
            f"**{t}**" if flag and (top is None or best_deep >= top) else t for t, _, flag in deep
        ]
        lines.append(f"| {beh} | {_num(own)} | " + " | ".join(cells) + " |")
    return lines


def return_table(result: dict[str, Any], variant: str) -> list[str]:
    """The return-based normalised score (exact) of the ceiling and the tabular learners on one twin."""
    tab_cols = list(TABULAR_COLUMNS)
    lines = [
        "| dataset | " + " | ".join(TABULAR_COLUMNS[c] for c in tab_cols) + " | seconds |",
        "|" + "---|" * (2 + len(tab_cols)),
    ]
    for beh, row in (result.get("tabular") or {}).items():
        cells = [_num(tabular_score(result, beh, c, variant, "return_normalized")) for c in tab_cols]
        lines.append(f"| {beh} | " + " | ".join(cells) + f" | {row.get('seconds', 0):.1f} |")
    return lines


def markdown(result: dict[str, Any]) -> str:
    """``bench.md``: the normalised score per twin (the table to quote), then every metric per run family."""
    cfg = result["config"]
    lines = _partial_line(result) + _heading(result)
    for v in cfg["variants"]:
        lines += ["", f"**{cfg['scene']} → {v}** (normalised score)", "", *score_table(result, v)]
    if result.get("tabular"):
        lines += _tabular_section(result)
    lines += _online_line(result)
    lines += _metrics_table(result)
    if result.get("ope"):
        lines += _ope_lines(result["ope"])
    lines += ["", _machine_line(result)]
    return "\n".join(lines) + "\n"


def _partial_line(result: dict[str, Any]) -> list[str]:
    """The first line of a report written before its benchmark finished (``"complete": false``), else nothing (a
    report of before this mark is taken as finished)."""
    if result.get("complete", True):
        return []
    tabular = ", then the tabular section" if result["config"].get("tabular") else ""
    return [
        f"**Partial results: {result['runs_done']} of {result['runs_planned']} runs finished{tabular}.** The "
        "benchmark stopped, or is still running, before the rest: run the same command again to finish it (the "
        "finished runs are reused).",
        "",
    ]


def _numerics(cfg: dict[str, Any]) -> str:
    """`` (batch 1024, bf16)`` where a benchmark's batch or precision is not 256 and fp32, else nothing (0 and auto
    are said as such: each run's results record what they resolved to)."""
    batch, precision = cfg.get("batch_size", 256), cfg.get("precision", "fp32")
    batch = batch or "auto"
    return f" (batch {batch}, {precision})" if (batch, precision) != (256, "fp32") else ""


def _heading(result: dict[str, Any]) -> list[str]:
    """What was trained and evaluated, and what the normalised score means (with the references)."""
    cfg = result["config"]
    refs = result.get("references") or {}
    return [
        f"Offline RL on `{cfg['scene']}`: d3rlpy algorithms trained on logged datasets of the blueprint twin, "
        f"{cfg['n_steps']} updates per run{_numerics(cfg)}, goals relabelled: {cfg.get('relabel', 'none')}, "
        f"{len(cfg['seeds'])} seed(s) ({', '.join(map(str, cfg['seeds']))}), "
        f"mean ± std over seeds; evaluated greedy and unshielded on {cfg['pairs']} seeded (start, target) pairs "
        "(seed 2024) of each twin.",
        "",
        _sensing_line(cfg),
        "",
        "Normalised score: 100 · (SPL − random) / (expert − random), 0 = uniformly random moves, 100 = the "
        "breadth-first shortest-path expert (dtradar_rl.evaluation.normalized); the best algorithm per dataset in bold."
        + (
            " References (SPL): "
            + "; ".join(f"{v} random {refs[v]['random']:.4f}, expert {refs[v]['expert']:.4f}" for v in refs)
            + "."
            if refs
            else ""
        ),
    ]


def _sensing_line(cfg: dict[str, Any]) -> str:
    """What the logged datasets hold and the agents observe (benchmarks from before sensings: privileged)."""
    sensing = cfg.get("sensing", "privileged")
    if sensing == "privileged":
        return (
            "Sensing: **privileged** (the `neighbors` preset: the robot's exact x, y and its neighbouring cells' "
            "radio; an upper bound, not navigation from radio)."
        )
    return (
        f"Sensing: **{sensing}**, honest (the logs record what the robot's own sensors read, receiver noise "
        f"{cfg.get('sensing_noise')}; the learners observe the localisation filter's belief along each episode, "
        "and are evaluated under the same noise, the tabular learners' tables followed through the same filter)."
    )


def _tabular_section(result: dict[str, Any]) -> list[str]:
    """The tabular learners' explanation and their return-based table per twin."""
    cfg = result["config"]
    if tabular_columns(result) is HONEST_TABULAR_COLUMNS:
        return [
            "",
            "Tabular columns (dtradar_rl.tabular.batch): CE, VI-LCB and Π_b-SPIBB are tables learnt from the logged "
            "cells and moves for every evaluation target, followed by a robot that is not told its cell: the "
            "localisation filter's belief votes for a move, and CE and VI-LCB are learnt again without the obstacles "
            "it senses (dtradar_rl.tabular.filter_table); rolled out on the same pairs and noise as the deep "
            "learners. No data ceiling and no return-based score: both are defined on the true cell.",
        ]
    lines = [
        "",
        "Tabular columns (dtradar_rl.tabular.batch): the data ceiling is the best SPL of any policy using only "
        "logged (cell, action) pairs, on the blueprint with the true cell; CE, VI-LCB and Π_b-SPIBB are tables "
        "learnt from the logged moves for every evaluation target (the reward function known, so every logged "
        "move teaches every target), acting by fingerprint localisation like a robot.",
    ]
    for v in cfg["variants"]:
        ref = next(iter(result["tabular"].values()))["return_references"].get(v) or {}
        lines += [
            "",
            f"**{cfg['scene']} → {v}** (return-based normalised score, exact: 100 · (J − J_random) / (J* − "
            f"J_random), J the mean discounted return (γ = {ref.get('gamma')}, reward {ref.get('reward')}) over "
            f"the evaluation pairs; J_random {ref.get('random', float('nan')):.3f}, J* "
            f"{ref.get('optimal', float('nan')):.3f})",
            "",
            *return_table(result, v),
        ]
    return lines


def _online_line(result: dict[str, Any]) -> list[str]:
    """The online agent the benchmark compares with, if it ran one."""
    online = result.get("online_dqn") or {}
    if not online:
        return []
    scores = ", ".join(
        f"{v} {_num((online.get(v) or {}).get('normalized'))} (success {online[v]['success_rate']:.3f})"
        for v in result["config"]["variants"]
        if v in online
    )
    return ["", f"Online reference: {online.get('label', 'DQN')} (`{online['checkpoint']}`): {scores}."]


def _metrics_table(result: dict[str, Any]) -> list[str]:
    """Every metric of every run family, each dataset's behaviour first."""
    variants = result["config"]["variants"]
    ope = result.get("ope")
    head = (
        "| dataset | policy | "
        + " | ".join(f"{v}: score | {v}: success | {v}: SPL | {v}: collisions/ep" for v in variants)
        + (" | FQE | true value" if ope else "")
        + " | train (s) |"
    )
    lines = ["", "Every metric (score = normalised score):", "", head]
    lines.append("|" + "---|" * (3 + 4 * len(variants) + (2 if ope else 0)))
    for beh, d in result["datasets"].items():
        lines.append(_behaviour_row(d, variants, bool(ope)))
        for e in (e for e in result["summary"] if e["behaviour"] == beh):
            cells = []
            for v in variants:
                m = e.get(v) or {}
                cells += [
                    _pm(m.get("normalized"), "{:.1f}"),
                    _pm(m.get("success_rate")),
                    _pm(m.get("spl")),
                    _pm(m.get("collisions"), "{:.2f}"),
                ]
            if ope:
                cells += [_pm(e.get("fqe")), _pm(e.get("true_value"))]
            lines.append(
                f"| {beh} | {result['algorithms'][e['algorithm']]} | "
                + " | ".join(cells)
                + f" | {e['train_s']['mean']:.1f} |"
            )
    return lines


def _behaviour_row(d: dict[str, Any], variants: list[str], ope: bool) -> str:
    """A dataset's own row: its behaviour rolled out (when it is one policy) and its logged episodes."""
    ev = d.get("eval") or {}
    blank = " | ".join(
        f"{_num(ev[v].get('normalized'))} | {ev[v]['success_rate']:.3f} | {ev[v]['spl']:.3f} | "
        f"{ev[v]['collisions']:.2f}"
        if v in ev
        else "- | - | - | -"
        for v in variants
    )
    logged_score = d.get("logged_score")
    return (
        f"| `{d['name']}`@{d['tag']} | behaviour itself ({'rolled out; ' if ev else 'no single policy; '}its "
        f"logged episodes on the blueprint: success {d['success_rate']:.3f} of finished episodes, "
        f"{d.get('reached_of_all', 0):.3f} of all; "
        + (f"normalised score {logged_score:.1f}; " if logged_score is not None else "")
        + f"mean return {d['mean_return']:.2f}, {d['episodes']} episodes, "
        f"{d.get('cut_by_end_of_log', 0)} cut by the end of logging) | {blank}{' | - | -' if ope else ''} | - |"
    )


def _ope_lines(ope: dict[str, Any]) -> list[str]:
    """How well FQE ranks the agents against their true values."""
    rho = "-" if ope["spearman"] is None else f"{ope['spearman']:.2f}"
    per = ", ".join(
        f"{b} {'-' if d['spearman'] is None else format(d['spearman'], '.2f')} ({d['n']})"
        for b, d in ope["per_dataset"].items()
    )
    return [
        "",
        f"FQE against the true value: Spearman rank correlation {rho} over {ope['n']} agents (per dataset: "
        f"{per}). Value = {ope['value']}; γ = {ope['gamma']}, {ope['fqe_steps']} FQE updates per agent.",
    ]


def _machine_line(result: dict[str, Any]) -> str:
    """Where and how the benchmark ran: machine, load, wall time, how the trainings were laid out."""
    mach = result["machine"]
    layout = result.get("layout") or {}
    return (
        f"Machine: {describe(mach['start'])}; load average (1/5/15 min) at start "
        f"{_load(mach['start'])}, at end {_load(mach['end'])}; total wall time {result['wall_s']:.0f} s"
        + (
            f", of which setup (references, online agent, datasets and their behaviours) {result['setup_s']:.0f} s"
            if "setup_s" in result
            else ""
        )
        + (
            f" ({layout['jobs']} trainings "
            + (
                f"as Ray tasks of one CPU ({layout.get('ray_address') or 'a local Ray'})"
                if layout.get("executor") == "ray"
                else f"in {layout['workers']} process(es)"
            )
            + ", one torch thread each"
            + _gain(layout.get("parallel_gain"))
            + ")."
            if layout
            else "."
        )
    )


def _gain(g: float | None) -> str:
    return "" if g is None else f"; {g:.2f}x the work with one process per core than with one, measured at the start"


def _load(m: dict[str, Any]) -> str:
    la = m.get("load_average")
    return "/".join(f"{x:.1f}" for x in la) if la else "-"


__all__ = [
    "SCORES",
    "TABULAR_COLUMNS",
    "aggregate",
    "best_per_dataset",
    "markdown",
    "ope_summary",
    "return_table",
    "score_table",
    "spearman",
    "summarize",
    "tabular_score",
]
