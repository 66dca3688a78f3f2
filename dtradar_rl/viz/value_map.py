"""A target's optimal values as a heat map with the greedy policy drawn as arrows (the Tabular RL page's picture)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dtradar_rl.viz.plots import _save, plt

#: ``(dx, dy)`` of the four moves (X-, X+, Y-, Y+), as arrows.
_ARROWS = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], np.float64)


def plot_value_grid(
    values: np.ndarray,
    actions: np.ndarray,
    target: tuple[int, int],
    path: Path,
    *,
    start: tuple[int, int] | None = None,
    route: np.ndarray | None = None,
    title: str = "",
) -> Path:
    """``values`` ``float[H, W]`` (NaN on blocked cells) as a heat map, ``actions`` ``int[H, W]`` (-1 on blocked
    cells) as one arrow per cell, the target as a star, and (``route``: ``int[k, 2]`` cells) the greedy path."""
    h, w = values.shape
    fig, ax = plt.subplots(figsize=(min(16.0, 2 + w * 0.22), min(12.0, 1.6 + h * 0.22)))
    im = ax.imshow(np.ma.masked_invalid(values), origin="lower", cmap="viridis", interpolation="nearest")
    ax.imshow(np.where(np.isnan(values), 1.0, np.nan), origin="lower", cmap="Greys", vmin=0, vmax=1.4)
    iy, ix = np.nonzero(actions >= 0)
    if ix.size <= 4000:  # more arrows than that is a grey blur: the route says it then
        d = _ARROWS[actions[iy, ix]]
        ax.quiver(ix, iy, d[:, 0], d[:, 1], angles="xy", scale_units="xy", scale=1.6, width=0.0025, color="white")
    if route is not None and len(route):
        ax.plot(route[:, 0], route[:, 1], color="tab:red", lw=2, label="greedy path")
    if start is not None:
        ax.plot(*start, "o", color="tab:red", ms=8, label="start")
    ax.plot(*target, "*", color="gold", mec="k", ms=16, label="target")
    fig.colorbar(im, ax=ax, shrink=0.8, label="V* (discounted return)")
    ax.set_xlabel("ix")
    ax.set_ylabel("iy")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return _save(fig, path)


__all__ = ["plot_value_grid"]
