"""Figures: training curves, navigation paths over the coverage map (paper Figs. 10, 22-24), cross-twin heatmaps."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dtradar_data.core.dataset import Dataset  # noqa: E402
from dtradar_data.core.files import open_atomic  # noqa: E402
from dtradar_data.geometry.floorplan import draw_floorplan  # noqa: E402
from dtradar_data.scenes import available_scenes, load_scene_spec  # noqa: E402


def _save(fig, path: Path) -> Path:
    """Save and close ``fig`` atomically: a killed run leaves the previous figure, not a truncated PNG."""
    path = Path(path)
    try:
        with open_atomic(path, "wb") as f:
            fig.savefig(f, format=path.suffix.lstrip(".") or "png", dpi=110)
    finally:
        plt.close(fig)
    return path


def moving_average(x: np.ndarray, k: int) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return x
    k = max(1, min(k, x.size))
    c = np.cumsum(np.insert(x, 0, 0.0))
    return (c[k:] - c[:-k]) / k


def plot_curves(episodes: Sequence[tuple], path: Path) -> Path:
    """Reward, steps and collisions per episode (moving averages) against environment steps."""
    fig, axes = plt.subplots(1, 4, figsize=(16, 3.4))
    if episodes:
        e = np.asarray(episodes, dtype=np.float64)
        k = max(1, len(e) // 50)
        x = e[k - 1 :, 1] if len(e) >= k else e[:, 1]
        for ax, col, label in zip(axes, (2, 3, 4, 5), ("reward", "steps", "collisions", "success rate")):
            ax.plot(e[:, 1], e[:, col], ".", ms=1, alpha=0.15, color="gray")
            ax.plot(x, moving_average(e[:, col], k), color="C0")
            ax.set_xlabel("environment steps")
            ax.set_title(f"{label} per episode (mean of {k})")
    fig.tight_layout()
    return _save(fig, path)


def _draw_obstacles(ax, ds: Dataset, extent) -> str:
    """Floor plan from the scene's file for a built-in scene, else (synthetic or imported tables) the blocked mask."""
    scene, _, variant = ds.name.partition("/")
    if scene in available_scenes():
        draw_floorplan(ax, load_scene_spec(scene, variant.partition("@")[0]))
        return "floorplan"
    mask = np.ma.masked_where(~ds.blocked, np.ones(ds.shape))
    ax.imshow(mask, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1.4, alpha=0.9, interpolation="nearest")
    return "blocked mask"


def plot_paths(
    ds: Dataset, paths: Sequence[Sequence[int]], path: Path, *, title: str = "", successes: Sequence[bool] | None = None
) -> Path:
    """Navigation paths (cell-index sequences) over the path-gain coverage map of ``ds``."""
    g = ds.grid_info
    extent = (
        g.x0_m - g.cell_m / 2,
        g.x0_m + (g.nx - 0.5) * g.cell_m,
        g.y0_m - g.cell_m / 2,
        g.y0_m + (g.ny - 0.5) * g.cell_m,
    )
    aspect = (extent[3] - extent[2]) / max(1e-9, extent[1] - extent[0])
    fig, ax = plt.subplots(figsize=(10, max(3.0, 10 * aspect + 1.2)))
    gain = ds.grid(["path_gain_db"])[..., 0]
    im = ax.imshow(gain, origin="lower", extent=extent, cmap="viridis", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="path gain (dB)", fraction=0.03)
    how = _draw_obstacles(ax, ds, extent)
    for k, p in enumerate(paths):
        iy, ix = np.divmod(np.asarray(p), g.nx)
        x, y = g.x0_m + ix * g.cell_m, g.y0_m + iy * g.cell_m
        ok = successes is None or successes[k]
        color = f"C{k % 10}"
        ax.plot(x, y, color=color, lw=2, ls="-" if ok else "--")
        ax.plot(x[0], y[0], "o", color=color, ms=7, mec="white")
        ax.plot(x[-1] if ok else x[-1], y[-1], "*" if ok else "x", color=color, ms=12, mec="white")
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or f"{ds.name}: navigation paths (o start, * reached, x failed; obstacles: {how})")
    fig.tight_layout()
    return _save(fig, path)


def plot_moving_paths(
    ds: Dataset,
    paths: Sequence[Sequence[int]],
    t0: Sequence[int],
    path: Path,
    *,
    title: str = "",
    successes: Sequence[bool] | None = None,
    frames: int | None = None,
) -> Path:
    """An animated picture of episodes on a moving twin: frame ``n`` shows step ``n`` of every path (robot o, target
    *, its trail), the movers' cells of each robot's snapshot ``(t0 + n) mod T`` in red (the first episode's snapshot
    when they differ) and the static obstacles in grey, over the path gain of that snapshot. Saved as a GIF."""
    from matplotlib.animation import FuncAnimation, PillowWriter

    g, T = ds.grid_info, ds.snapshots
    extent = (
        g.x0_m - g.cell_m / 2,
        g.x0_m + (g.nx - 0.5) * g.cell_m,
        g.y0_m - g.cell_m / 2,
        g.y0_m + (g.ny - 0.5) * g.cell_m,
    )
    snaps = [ds.snapshot(k) for k in range(T)]
    gains = [s.grid(["path_gain_db"])[..., 0] for s in snaps]
    movers = [s.table.column("mover").to_numpy(zero_copy_only=False).reshape(g.ny, g.nx) for s in snaps]
    walls = snaps[0].blocked & ~movers[0]
    xy = [np.divmod(np.asarray(p), g.nx) for p in paths]
    n_frames = frames or max(len(p) for p in paths)
    aspect = (extent[3] - extent[2]) / max(1e-9, extent[1] - extent[0])
    fig, ax = plt.subplots(figsize=(9, max(3.0, 9 * aspect + 1.0)))
    lo, hi = np.nanmin(np.stack(gains)), np.nanmax(np.stack(gains))
    im = ax.imshow(gains[t0[0] % T], origin="lower", extent=extent, cmap="viridis", vmin=lo, vmax=hi)
    fig.colorbar(im, ax=ax, label="path gain (dB)", fraction=0.03)
    grey = np.ma.masked_where(~walls, np.ones(walls.shape))
    ax.imshow(grey, origin="lower", extent=extent, cmap="Greys", vmin=0, vmax=1.4, interpolation="nearest")
    red = ax.imshow(
        np.ma.masked_where(~movers[t0[0] % T], np.ones(walls.shape)),
        origin="lower",
        extent=extent,
        cmap="Reds",
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )
    trails, robots = [], []
    for k, (iy, ix) in enumerate(xy):
        c = f"C{k % 10}"
        x, y = g.x0_m + ix * g.cell_m, g.y0_m + iy * g.cell_m
        ax.plot(x[-1], y[-1], "*", color=c, ms=12, mec="white")  # where it ended (the target when reached)
        trails.append(ax.plot([], [], color=c, lw=2, ls="-" if successes is None or successes[k] else "--")[0])
        robots.append(ax.plot([], [], "o", color=c, ms=8, mec="white")[0])
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")

    def draw(n: int):
        t = (int(t0[0]) + n) % T
        im.set_data(gains[t])
        red.set_data(np.ma.masked_where(~movers[t], np.ones(walls.shape)))
        for k, (iy, ix) in enumerate(xy):
            m = min(n, len(ix) - 1)
            x, y = g.x0_m + ix[: m + 1] * g.cell_m, g.y0_m + iy[: m + 1] * g.cell_m
            trails[k].set_data(x, y)
            robots[k].set_data(x[-1:], y[-1:])
        ax.set_title((title or ds.name) + f"\nstep {n}, snapshot {t} of {T} (movers red)", fontsize=9)
        return [im, red, *trails, *robots]

    anim = FuncAnimation(fig, draw, frames=n_frames, blit=False)
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    try:
        anim.save(tmp, writer=PillowWriter(fps=4))
        tmp.replace(path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return path


def plot_matrix(
    matrix: np.ndarray,
    rows: Sequence[str],
    cols: Sequence[str],
    path: Path,
    *,
    title: str = "success rate",
    fmt: str = "{:.2f}",
) -> Path:
    """A train x evaluation heatmap (e.g. the cities' cross-quadrant matrix)."""
    m = np.asarray(matrix, np.float64)
    fig, ax = plt.subplots(figsize=(1.4 * len(cols) + 2.5, 1.1 * len(rows) + 1.8))
    im = ax.imshow(m, cmap="magma", vmin=0, vmax=1)
    ax.set_xticks(range(len(cols)), cols, rotation=30, ha="right")
    ax.set_yticks(range(len(rows)), rows)
    ax.set_xlabel("evaluated on")
    ax.set_ylabel("trained on")
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            ax.text(j, i, fmt.format(m[i, j]), ha="center", va="center", color="white" if m[i, j] < 0.6 else "black")
    fig.colorbar(im, ax=ax, fraction=0.05)
    ax.set_title(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_adapt_curves(curves: dict[str, Sequence[dict]], path: Path, *, title: str = "") -> Path:
    """Success (solid) and SPL (dashed) against training seconds, one colour per run (fine-tune, plain fine-tune,
    scratch)."""
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for k, (run, rows) in enumerate(curves.items()):
        t = [r["train_s"] for r in rows]
        ax.plot(t, [r["success_rate"] for r in rows], "-o", ms=3, color=f"C{k}", label=f"{run}: success")
        ax.plot(t, [r["spl"] for r in rows], "--", color=f"C{k}", alpha=0.6, label=f"{run}: SPL")
    ax.axhline(0.99, color="grey", lw=0.8, ls=":")
    ax.set(xlabel="training seconds", ylabel="on the changed twin", ylim=(0, 1.02), title=title)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def plot_adapt_seeds(runs: dict[str, Sequence[Sequence[dict]]], path: Path, *, title: str = "") -> Path:
    """Success against training seconds of several seeds per run (fine-tune, plain fine-tune, scratch): one colour
    per run, a thin line per seed; the right panel zooms into 0.9-1.0, where the 0.99 goal line is."""
    fig, axes = plt.subplots(1, 2, figsize=(10.5, 3.8))
    for ax, lo in zip(axes, (0.0, 0.9), strict=True):
        for k, (run, seeds) in enumerate(runs.items()):
            for j, rows in enumerate(seeds):
                ax.plot(
                    [r["train_s"] for r in rows],
                    [r["success_rate"] for r in rows],
                    "-o",
                    ms=2.5,
                    lw=1.1,
                    color=f"C{k}",
                    alpha=0.85,
                    label=f"{run} ({len(seeds)} seeds)" if j == 0 else None,
                )
        ax.axhline(0.99, color="grey", lw=0.8, ls=":")
        ax.set(xlabel="training seconds", ylim=(lo, 1.005 if lo else 1.02))
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success on the changed twin")
    axes[1].set_title("zoom: 0.9-1.0 (dotted: 0.99)", fontsize=9)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
