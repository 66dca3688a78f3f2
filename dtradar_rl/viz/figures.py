"""The paper's figures that :mod:`dtradar_rl.viz.plots` does not draw: training curves per episode with the paper's
minimum beside ours (Figs. 9, 11-16, 18-21) and the cross-quadrant bars (Fig. 17)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dtradar_rl.viz.plots import _save, moving_average, plt


def plot_episode_curves(
    episodes: Sequence[tuple], path: Path, *, shortest: int | None = None, paper_min: int | None = None, title: str = ""
) -> Path:
    """Reward, steps and collisions per training episode (as the paper plots them), with the breadth-first optimum
    and the paper's minimum steps drawn on the steps panel. ``episodes``: rows ``(episode, env_step, reward,
    steps, collisions, success)`` as :func:`dtradar_rl.train.dqn.train` writes them to ``curves.csv``."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.6))
    e = np.asarray(episodes, dtype=np.float64).reshape(-1, 6)
    k = max(1, len(e) // 25)
    for ax, col, label in zip(axes, (2, 3, 4), ("reward", "steps", "collisions")):
        if len(e):
            ax.plot(e[:, 0] + 1, e[:, col], ".", ms=3, alpha=0.35, color="gray", label="per episode")
            if len(e) >= k > 1:
                ax.plot(e[k - 1 :, 0] + 1, moving_average(e[:, col], k), color="C0", label=f"mean of {k}")
        ax.set_xlabel("episode")
        ax.set_title(f"{label} per episode")
        if col == 3:
            ax.set_yscale("log")
            if shortest:
                ax.axhline(shortest, color="C2", ls="--", label=f"shortest path ({shortest})")
            if paper_min:
                ax.axhline(paper_min, color="C3", ls=":", label=f"paper's minimum ({paper_min}, its grid)")
        if col == 2 and len(e):
            ax.set_yscale("symlog")
        ax.legend(fontsize=7, loc="best")
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


__all__ = ["plot_episode_curves", "plot_bars"]
