"""The offline benchmark's figures: the normalised score per dataset and algorithm beside the behaviour and the
tabular learners (``bench.png``), and FQE's estimates against the true values (``fqe.png``). The tables are
:mod:`dtradar_rl.experiments.offline_report`'s."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dtradar_rl.experiments.offline_report import tabular_columns, tabular_score


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
                max((tabular_score(result, b, c, v) for c in tabular_columns(result) if c != "ceiling"), default=np.nan)
                for b in behs
            ]
            ax.scatter(x, best, marker="*", s=80, color="gold", edgecolor="k", zorder=4, label="best tabular")
            ceil = [tabular_score(result, b, "ceiling", v) for b in behs]
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


__all__ = ["plot", "plot_fqe"]
