"""The build options that replace part of a scene: ``--cell-m``, ``--grid``, ``--tx`` and ``--osm``, checked as values.

:func:`check_scene_options` runs first thing in :func:`~dtradar_data.scenes.load_scene_spec`, before any scene file,
mesh or footprint source is read (an ``--osm`` download, the hashing of an XML's meshes), so a NaN, a zero or negative
cell size, an empty source or a grid far too large for memory fails at once with an
:class:`~dtradar_data.core.errors.InvalidSettingError` that names the flag. Whether an option applies to the scene
(``--cell-m`` to a room, ``--grid`` to a city) is the loader's business; a value of 0 or ``""`` is a value, never
"not given" (only None is).
"""

from __future__ import annotations

import math
from typing import Any

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.grid import MAX_CELLS, Grid, grid_problem, too_many_cells

__all__ = [
    "check_cell_m",
    "check_footprints",
    "check_scene_options",
    "grid_from_option",
    "grid_with_cell",
    "tx_from_option",
]

GRID_EXAMPLE = "e.g. --grid -100 -100 5 40 40 (X0 Y0 CELL_M NX NY: the centre of cell 0, 0 and the cell size in metres)"


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def check_cell_m(cell_m: Any) -> float | None:
    """``--cell-m`` as a float: None (not given) or a finite number of metres > 0."""
    if cell_m is None:
        return None
    if not _finite(cell_m) or cell_m <= 0:
        raise InvalidSettingError(
            f"--cell-m {cell_m!r} is not a cell size: it must be a finite number of metres > 0",
            hint="e.g. --cell-m 2 (smaller cells are finer and slower); drop it to keep the scene's own cell size",
        )
    return float(cell_m)


def check_footprints(footprints: Any) -> str | None:
    """``--osm``: None (not given) or a non-empty source (a file path, or ``osm``)."""
    if footprints is None:
        return None
    if not isinstance(footprints, str) or not footprints.strip():
        raise InvalidSettingError(
            f"--osm {footprints!r} names no footprint source",
            hint='give a GeoJSON or .osm file, or "osm" to download; drop --osm to use the city file\'s source',
        )
    return footprints


def grid_from_option(grid: Any) -> Grid:
    """``--grid X0 Y0 CELL_M NX NY`` as a :class:`Grid`: finite numbers, cells > 0, at most ``MAX_CELLS`` cells."""
    try:
        x0, y0, cell, nx, ny = grid
    except (TypeError, ValueError) as e:
        raise InvalidSettingError(f"--grid {grid!r}: expected X0 Y0 CELL_M NX NY", hint=GRID_EXAMPLE) from e
    problem = grid_problem(x0, y0, cell, nx, ny, names=("X0", "Y0", "CELL_M", "NX", "NY"))
    if problem:
        raise InvalidSettingError(
            f"--grid {' '.join(str(v) for v in grid)}: {problem}", hint=f"{GRID_EXAMPLE}; at most {MAX_CELLS:,} cells"
        )
    return Grid(float(x0), float(y0), float(cell), int(nx), int(ny))


def grid_with_cell(grid: Grid, cell_m: float) -> Grid:
    """The same area as ``grid`` in cells of ``cell_m`` (``--cell-m`` on an XML scene); too many cells name the flag."""
    x0, y0, x1, y1 = grid.bounds()
    nx, ny = max(1, round((x1 - x0) / cell_m)), max(1, round((y1 - y0) / cell_m))
    problem = too_many_cells(nx, ny)
    if problem:
        raise InvalidSettingError(
            f"--cell-m {cell_m:g} over {x1 - x0:g} x {y1 - y0:g} m: {problem}",
            hint=f"use larger cells (--cell-m), at most {MAX_CELLS:,} cells",
        )
    return Grid(x0 + cell_m / 2, y0 + cell_m / 2, float(cell_m), nx, ny)


def tx_from_option(tx: Any) -> tuple[float, float, float]:
    """``--tx X Y Z`` as three finite floats (metres)."""
    if not (
        isinstance(tx, (list, tuple)) and len(tx) == 3 and all(_finite(v) for v in tx)
    ):  # a NaN would otherwise reach the version hash, an infinity the ray tracer
        raise InvalidSettingError(
            f"--tx {' '.join(str(v) for v in tx) if isinstance(tx, (list, tuple)) else repr(tx)}: "
            "expected X Y Z, three finite numbers of metres",
            hint="e.g. --tx 0 0 20",
        )
    return tuple(float(v) for v in tx)  # type: ignore[return-value]


def check_scene_options(*, footprints: Any = None, cell_m: Any = None, grid: Any = None, tx: Any = None) -> None:
    """Every option's value, before any scene is read; :class:`InvalidSettingError` names the flag."""
    check_footprints(footprints)
    check_cell_m(cell_m)
    if grid is not None:
        grid_from_option(grid)
    if tx is not None:
        tx_from_option(tx)
