"""The picture of a built table itself (``cells.png`` beside ``cells.parquet``): each cell's ``path_gain_db`` as
stored, one panel per transmitter, all on one dB scale, blocked cells and cells without a path drawn as such.

Sionna's radio map (``coverage.png``, :mod:`.coverage`) is a separate solver's estimate on a finer grid; this picture
shows what an agent reads, cell for cell, so a hole or a bad transmitter placement in the table shows where the radio
map would smooth it over.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa

from dtradar_data.core.schema import tx_column

BLOCKED_COLOUR = "#4d4d4d"  # obstacles: dark, apart from every colour of the dB map
NO_PATH_COLOUR = "#ffffff"  # free cells no path reaches: the map's absence of signal
MAX_COLUMNS = 4  # panels per row: ten transmitters (Munich) still read at a glance


def gain_grids(cells: pa.Table, nx: int, ny: int, transmitters: int) -> list[np.ndarray]:
    """``[ny, nx]`` float arrays of each transmitter's ``path_gain_db`` (NaN where the table holds none), placed by
    the rows' own ``ix``, ``iy`` so the picture never depends on the table's row order."""
    ix, iy = cells.column("ix").to_numpy(), cells.column("iy").to_numpy()
    grids = []
    for k in range(transmitters):
        grid = np.full((ny, nx), np.nan)
        values = cells.column(tx_column("path_gain_db", k)).to_numpy(zero_copy_only=False)
        grid[iy, ix] = np.asarray(values, dtype=float)  # nulls arrive as NaN
        grids.append(grid)
    return grids


def render_cells_png(spec, cells: pa.Table, blocked: np.ndarray, path: Path) -> Path:
    """Draw ``cells`` (the table as it will be stored) into ``path``: one panel per transmitter on one dB colour
    scale (the free cells' 2nd percentile to their maximum over every transmitter), blocked cells dark grey, free
    cells without a path white, each transmitter a red star."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    g, txs = spec.grid, spec.transmitters
    grids = gain_grids(cells, g.nx, g.ny, len(txs))
    free = np.concatenate([d[~blocked] for d in grids])
    finite = free[np.isfinite(free)]
    lo, hi = (float(np.percentile(finite, 2)), float(finite.max())) if finite.size else (None, None)
    extent = (
        g.x0_m - g.cell_m / 2,
        g.x0_m + (g.nx - 0.5) * g.cell_m,
        g.y0_m - g.cell_m / 2,
        g.y0_m + (g.ny - 0.5) * g.cell_m,
    )
    cols = min(len(txs), MAX_COLUMNS)
    rows = math.ceil(len(txs) / cols)
    aspect = g.ny / g.nx
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols + 1.2, max(3.0, 4.2 * aspect) * rows + 0.6), squeeze=False)
    for k, ax in enumerate(axes.flat):
        if k >= len(txs):
            ax.set_visible(False)
            continue
        ax.imshow(np.where(blocked, np.nan, 1.0), origin="lower", extent=extent, cmap=ListedColormap([NO_PATH_COLOUR]))
        im = ax.imshow(
            np.where(blocked, np.nan, grids[k]), origin="lower", extent=extent, cmap="viridis", vmin=lo, vmax=hi
        )
        ax.imshow(np.where(blocked, 1.0, np.nan), origin="lower", extent=extent, cmap=ListedColormap([BLOCKED_COLOUR]))
        x, y, _ = txs[k].position_m
        ax.plot([x], [y], marker="*", color="red", markersize=12, markeredgecolor="black")
        ax.set_title(f"transmitter {k}" + (f" ({txs[k].name})" if txs[k].name else "") if len(txs) > 1 else "")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    fig.colorbar(im, ax=axes.ravel().tolist(), label=f"path_gain_db at z = {spec.rx_height_m} m (one scale)")
    legend = [
        Patch(color=BLOCKED_COLOUR, label="blocked"),
        Patch(facecolor=NO_PATH_COLOUR, edgecolor="black", label="no path"),
    ]
    axes.flat[0].legend(handles=legend, loc="upper right", fontsize=8)
    fig.suptitle(f"{spec.name}: the cell table (cells.parquet), path gain per cell")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
