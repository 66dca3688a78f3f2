"""Coverage maps: the RadioMapSolver path gain over a scene's grid, with the floor plan drawn on top (paper Figs. 5
and 7)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dtradar_data.geometry.floorplan import draw_floorplan

COVERAGE_SUBCELLS = 4  # radio-map cells per grid cell side: the map is finer than the table


def render_coverage_png(spec, tracer, path: Path, *, samples: int) -> Path:
    """RadioMapSolver path gain over the grid (4 sub-cells per cell side), obstacles drawn on top (paper Figs. 5
    and 7)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = spec.grid
    width, height = g.nx * g.cell_m, g.ny * g.cell_m
    x_lo, y_lo = g.x0_m - g.cell_m / 2, g.y0_m - g.cell_m / 2
    centre = (x_lo + width / 2, y_lo + height / 2, spec.rx_height_m)
    gain = tracer.radio_map(
        centre_m=centre, size_m=(width, height), cell_m=g.cell_m / COVERAGE_SUBCELLS, samples_per_tx=samples
    )
    with np.errstate(divide="ignore"):
        db = 10 * np.log10(gain)
    db[~np.isfinite(db)] = np.nan
    fig, ax = plt.subplots(
        figsize=(max(6.0, width / max(width, height) * 10), max(4.0, height / max(width, height) * 8))
    )
    im = ax.imshow(
        db,
        origin="lower",
        extent=(x_lo, x_lo + width, y_lo, y_lo + height),
        cmap="viridis",
        vmin=np.nanpercentile(db, 2) if np.isfinite(db).any() else None,
    )
    draw_floorplan(ax, spec)
    fig.colorbar(im, ax=ax, label=f"path gain [dB] at z = {spec.rx_height_m} m")
    ax.set_title(f"{spec.name}: coverage map, {tracer.settings.frequency_hz / 1e9:g} GHz")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
