"""The paper's figures that :mod:`dtradar_rl.viz.plots` does not draw: training curves per episode over seeds with the
paper's minimum beside ours (Figs. 9, 11-16, 18-21) and the cross-quadrant bars (Fig. 17)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dtradar_rl.viz.plots import _save, moving_average, plt


def plot_seed_curves(
    runs: dict[int, Sequence[tuple]],
    path: Path,
    *,
    shortest: int | None = None,
    paper_min: int | None = None,
    title: str = "",
) -> Path:
    """Steps and collisions per training episode of one pair over several seeds: each seed's moving average as a
    thin line, the median over seeds bold, and the fewest steps found so far per seed (the paper's Table VI number is
    that minimum; the spread is what one seed cannot show). ``runs``: seed -> rows of ``curves.csv``."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.6))
    series = {s: np.asarray(e, dtype=np.float64).reshape(-1, 6) for s, e in runs.items()}
    n = max((len(e) for e in series.values()), default=0)
    k = max(1, n // 25)
    for ax, col, label in zip(axes[:2], (3, 4), ("steps", "collisions")):
        stack = np.full((len(series), n), np.nan)
        for i, (seed, e) in enumerate(series.items()):
            stack[i, : len(e)] = e[:, col]
            if len(e) >= k:
                ax.plot(e[k - 1 :, 0] + 1, moving_average(e[:, col], k), lw=0.8, alpha=0.6, label=f"seed {seed}")
        if n:
            with np.errstate(all="ignore"):
                med = np.nanmedian(stack, axis=0)
            ax.plot(np.arange(n)[k - 1 :] + 1, moving_average(med, k), color="k", lw=2, label="median over seeds")
        ax.set_yscale("symlog" if col == 4 else "log")
        ax.set_xlabel("episode")
        ax.set_title(f"{label} per episode (mean of {k})")
    ax = axes[2]
    for seed, e in series.items():
        reached = e[:, 5] > 0
        best = np.where(reached, e[:, 3], np.inf)
        run_min = np.minimum.accumulate(best) if len(best) else best
        ok = np.isfinite(run_min)
        ax.step(e[ok, 0] + 1, run_min[ok], where="post", lw=1, label=f"seed {seed}")
    ax.set_yscale("log")
    ax.set_xlabel("episode")
    ax.set_title("fewest steps to the target so far")
    for a in axes[:3:2]:
        if shortest:
            a.axhline(shortest, color="C2", ls="--", label=f"shortest path ({shortest})")
        if paper_min:
            a.axhline(paper_min, color="C3", ls=":", label=f"paper's minimum ({paper_min}, its grid)")
    for a in axes:
        a.legend(fontsize=6, loc="best", ncol=2)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_bars(
    matrix, rows: Sequence[str], cols: Sequence[str], path: Path, *, ylabel: str = "success rate", title: str = ""
) -> Path:
    """Grouped bars of a train x evaluation matrix: one group per evaluated twin, one bar per trained agent
    (the paper's Fig. 17 shows cross-quadrant inference this way)."""
    m = np.asarray(matrix, np.float64)
    fig, ax = plt.subplots(figsize=(1.6 * len(cols) + 3, 3.8))
    width = 0.8 / max(1, len(rows))
    x = np.arange(len(cols))
    for i, r in enumerate(rows):
        bars = ax.bar(x + (i - (len(rows) - 1) / 2) * width, m[i], width, label=f"trained on {r}")
        ax.bar_label(bars, fmt="%.2f", fontsize=6, padding=1)
    ax.set_xticks(x, [f"on {c}" for c in cols])
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 1.12)
    ax.legend(fontsize=7, ncol=min(4, len(rows)), loc="upper center", bbox_to_anchor=(0.5, -0.12))
    ax.set_title(title or f"{ylabel}: trained on one twin, evaluated on each")
    fig.tight_layout()
    return _save(fig, path)


__all__ = ["plot_seed_curves", "plot_bars"]
