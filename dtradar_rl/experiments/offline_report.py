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
from pathlib import Path
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


def _tabular_score(result: dict[str, Any], beh: str, column: str, variant: str, key: str = "normalized"):
    row = ((result.get("tabular") or {}).get(beh) or {}).get(column) or {}
    return (row.get(variant) or {}).get(key)


def score_table(result: dict[str, Any], variant: str) -> list[str]:
    """The quotable table of one twin: a row per dataset, the behaviour itself, the data's ceiling and the tabular
    batch learners (when the benchmark ran them), then every d3rlpy algorithm's normalised score (mean ± std over
    seeds); the best learner of each row (tabular or deep, not the ceiling) in bold."""
    algos = list(result["algorithms"])
    tab_cols = [c for c in TABULAR_COLUMNS if result.get("tabular")]
    best = best_per_dataset(result, variant)
    lines = [
        "| "
        + " | ".join(["dataset", "behaviour itself", *(TABULAR_COLUMNS[c] for c in tab_cols)])
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
        tab = [(c, _tabular_score(result, beh, c, variant)) for c in tab_cols]
        top = max([x for _, x in tab[1:] if x is not None] + [x for _, x, _ in deep if x is not None], default=None)
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
        cells = [_num(_tabular_score(result, beh, c, variant, "return_normalized")) for c in tab_cols]
        lines.append(f"| {beh} | " + " | ".join(cells) + f" | {row.get('seconds', 0):.1f} |")
    return lines


def markdown(result: dict[str, Any]) -> str:
    """``bench.md``: the normalised score per twin (the table to quote), then every metric per run family."""
    cfg = result["config"]
    variants = cfg["variants"]
    ope = result.get("ope")
    refs = result.get("references") or {}
    lines = [
        f"Offline RL on `{cfg['scene']}`: d3rlpy algorithms trained on logged datasets of the blueprint twin, "
        f"{cfg['n_steps']} updates per run, goals relabelled: {cfg.get('relabel', 'none')}, "
        f"{len(cfg['seeds'])} seed(s) ({', '.join(map(str, cfg['seeds']))}), "
        f"mean ± std over seeds; evaluated greedy and unshielded on {cfg['pairs']} seeded (start, target) pairs "
        "(seed 2024) of each twin.",
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
    for v in variants:
        lines += ["", f"**{cfg['scene']} → {v}** (normalised score)", "", *score_table(result, v)]
    if result.get("tabular"):
        lines += [
            "",
            "Tabular columns (dtradar_rl.tabular.batch): the data ceiling is the best SPL of any policy using only "
            "logged (cell, action) pairs, on the blueprint with the true cell; CE, VI-LCB and Π_b-SPIBB are tables "
            "learnt from the logged moves for every evaluation target (the reward function known, so every logged "
            "move teaches every target), acting by fingerprint localisation like a robot.",
        ]
        for v in variants:
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
    online = result.get("online_dqn") or {}
    if online:
        scores = ", ".join(
            f"{v} {_num((online.get(v) or {}).get('normalized'))} (success {online[v]['success_rate']:.3f})"
            for v in variants
            if v in online
        )
        lines += ["", f"Online reference: {online.get('label', 'DQN')} (`{online['checkpoint']}`): {scores}."]
    head = (
        "| dataset | policy | "
        + " | ".join(f"{v}: score | {v}: success | {v}: SPL | {v}: collisions/ep" for v in variants)
        + (" | FQE | true value" if ope else "")
        + " | train (s) |"
    )
    no_ope = " | - | -" if ope else ""
    lines += ["", "Every metric (score = normalised score):", "", head]
    lines.append("|" + "---|" * (3 + 4 * len(variants) + (2 if ope else 0)))
    for beh, d in result["datasets"].items():
        ev = d.get("eval") or {}
        blank = " | ".join(
            f"{_num(ev[v].get('normalized'))} | {ev[v]['success_rate']:.3f} | {ev[v]['spl']:.3f} | "
            f"{ev[v]['collisions']:.2f}"
            if v in ev
            else "- | - | - | -"
            for v in variants
        )
        logged_score = d.get("logged_score")
        lines.append(
            f"| `{d['name']}`@{d['tag']} | behaviour itself ({'rolled out; ' if ev else 'no single policy; '}its "
            f"logged episodes on the blueprint: success {d['success_rate']:.3f} of finished episodes, "
            f"{d.get('reached_of_all', 0):.3f} of all; "
            + (f"normalised score {logged_score:.1f}; " if logged_score is not None else "")
            + f"mean return {d['mean_return']:.2f}, {d['episodes']} episodes, "
            f"{d.get('cut_by_end_of_log', 0)} cut by the end of logging) | {blank}{no_ope} | - |"
        )
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
    if ope:
        rho = "-" if ope["spearman"] is None else f"{ope['spearman']:.2f}"
        per = ", ".join(
            f"{b} {'-' if d['spearman'] is None else format(d['spearman'], '.2f')} ({d['n']})"
            for b, d in ope["per_dataset"].items()
        )
        lines += [
            "",
            f"FQE against the true value: Spearman rank correlation {rho} over {ope['n']} agents (per dataset: "
            f"{per}). Value = {ope['value']}; γ = {ope['gamma']}, {ope['fqe_steps']} FQE updates per agent.",
        ]
    mach = result["machine"]
    layout = result.get("layout") or {}
    lines += [
        "",
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
        ),
    ]
    return "\n".join(lines) + "\n"


def _gain(g: float | None) -> str:
    return "" if g is None else f"; {g:.2f}x the work with one process per core than with one, measured at the start"


def _load(m: dict[str, Any]) -> str:
    la = m.get("load_average")
    return "/".join(f"{x:.1f}" for x in la) if la else "-"


def plot(result: dict[str, Any], path: Path) -> Path:
    """Normalised-score bars per dataset and algorithm, one panel per twin, error bars = std over seeds; the
    behaviour itself as a cross, the best tabular learner as a star and the data's ceiling as a bar across the
    group (when the benchmark ran them), the expert's 100 dotted, the online agent dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = result["config"]["variants"]
    behs = list(result["datasets"])
    algos = list(result["algorithms"])
    fig, axes = plt.subplots(1, len(variants), figsize=(6.0 * len(variants), 4.4), squeeze=False)
    width = 0.8 / max(1, len(algos))
    for ax, v in zip(axes[0], variants):
        x = np.arange(len(behs))
        for k, a in enumerate(algos):
            means, stds = [], []
            for b in behs:
                e = next((e for e in result["summary"] if e["behaviour"] == b and e["algorithm"] == a), {})
                m = (e.get(v) or {}).get("normalized") or {"mean": np.nan, "std": 0.0}
                means.append(m["mean"])
                stds.append(m["std"])
            ax.bar(
                x + (k - (len(algos) - 1) / 2) * width,
                means,
                width,
                yerr=stds,
                capsize=2,
                label=result["algorithms"][a],
            )
        own = [((result["datasets"][b].get("eval") or {}).get(v) or {}).get("normalized", np.nan) for b in behs]
        ax.scatter(x, own, marker="x", color="k", zorder=3, label="behaviour itself")
        if result.get("tabular"):  # the best tabular learner as a star, the data's ceiling as a bar across the group
            best = [
                max((_tabular_score(result, b, c, v) for c in TABULAR_COLUMNS if c != "ceiling"), default=np.nan)
                for b in behs
            ]
            ax.scatter(x, best, marker="*", s=80, color="gold", edgecolor="k", zorder=4, label="best tabular")
            ceil = [_tabular_score(result, b, "ceiling", v) for b in behs]
            ceil = [np.nan if c is None else c for c in ceil]
            ax.hlines(ceil, x - 0.42, x + 0.42, colors="k", lw=1.5, zorder=3, label="data ceiling")
        ax.axhline(100, color="0.5", ls=":", lw=1, label="expert (100)")
        online = (result.get("online_dqn") or {}).get(v) or {}
        if "normalized" in online:
            ax.axhline(online["normalized"], color="k", ls="--", lw=1, label="online agent")
        ax.axhline(0, color="0.5", lw=0.8)
        ax.set_xticks(x, behs, rotation=15)
        ax.set_ylim(min(-10.0, np.nanmin([*own, 0.0]) - 5), 125)
        ax.set_ylabel("normalised score (0 random, 100 expert)")
        ax.set_title(f"{result['config']['scene']} → {v}")
    axes[0][-1].legend(fontsize=7, loc="upper right", ncol=3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_fqe(result: dict[str, Any], path: Path) -> Path:
    """FQE's estimate against the true value, one point per trained agent (colour: algorithm, marker: dataset),
    the diagonal, and the Spearman rank correlation in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in result["runs"] if "fqe" in r and "true_value" in r]
    algos, behs = list(result["algorithms"]), list(result["datasets"])
    markers = "osD^vP*X"
    fig, ax = plt.subplots(figsize=(5.6, 4.8))
    for r in runs:
        k = algos.index(r["algorithm"])
        ax.scatter(
            r["true_value"], r["fqe"], color=f"C{k}", marker=markers[behs.index(r["behaviour"]) % len(markers)], s=28
        )
    if runs:
        vals = [r["true_value"] for r in runs] + [r["fqe"] for r in runs]
        lo, hi = min(vals), max(vals)
        pad = 0.05 * (hi - lo or 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.6", lw=1, ls="--", label="FQE = true")
    for k, a in enumerate(algos):
        ax.scatter([], [], color=f"C{k}", marker="o", label=result["algorithms"][a])
    for j, b in enumerate(behs):
        ax.scatter([], [], color="k", marker=markers[j % len(markers)], label=b)
    ope = result.get("ope") or {}
    rho = ope.get("spearman")
    ax.set_title(
        f"{result['config']['scene']}: FQE vs true value, Spearman ρ = {'-' if rho is None else f'{rho:.2f}'} "
        f"({len(runs)} agents)",
        fontsize=10,
    )
    ax.set_xlabel(f"true value (rollouts on the twin, γ = {ope.get('gamma', '-')})")
    ax.set_ylabel("FQE estimate (logged data only)")
    ax.legend(fontsize=7, loc="lower right", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


__all__ = [
    "SCORES",
    "aggregate",
    "best_per_dataset",
    "markdown",
    "ope_summary",
    "plot",
    "plot_fqe",
    "score_table",
    "spearman",
    "summarize",
]
