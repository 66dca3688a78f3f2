"""The receiver grid: square cells over the scene's floor, indexed ``[iy, ix]`` (row-major, y outer).

One class for the grid of a scene description and the grid recorded in a stored dataset's metadata. A grid is checked
when it is made (:func:`grid_problem`): a finite origin, cells of a finite positive size, and at most
:data:`MAX_CELLS` cells, so a mistyped size fails at once instead of in a huge allocation before the first trace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError
from dtradar_data.core.files import human_size

#: The most cells a grid may have (2000 x 2000). Far above every built-in scene (the largest, Sionna's cities, have
#: 6400), and far above what a build traces in a day; beyond it the per-cell arrays alone no longer fit in memory.
MAX_CELLS = 4_000_000
#: Memory per cell of a build's arrays over the grid (occupancy, receiver points, the cell table's columns and their
#: temporaries), without paths: what :func:`too_many_cells` quotes.
BYTES_PER_CELL = 200


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _show(value: Any) -> str:
    return str(value) if _is_number(value) else repr(value)


def too_many_cells(nx: int, ny: int) -> str | None:
    """Why an ``nx`` x ``ny`` grid is too large (its cell count and the memory it would take), or None."""
    n = int(nx) * int(ny)
    if n <= MAX_CELLS:
        return None
    return (
        f"{nx} x {ny} = {n:,} cells is more than the {MAX_CELLS:,} a grid may have (its per-cell arrays alone "
        f"would take about {human_size(n * BYTES_PER_CELL)} of memory)"
    )


def grid_problem(
    x0_m: Any,
    y0_m: Any,
    cell_m: Any,
    nx: Any,
    ny: Any,
    *,
    names: tuple[str, ...] = ("x0_m", "y0_m", "cell_m", "nx", "ny"),
) -> str | None:
    """What is wrong with these grid values (a non-finite origin or cell size, a cell size <= 0, a cell count that
    is not a positive integer, too many cells), or None when they make a grid. ``names`` are the five values' names
    in the message (``("X0", "Y0", "CELL_M", "NX", "NY")`` for ``--grid``)."""
    for name, value in zip(names[:3], (x0_m, y0_m, cell_m)):
        if not _is_number(value) or not math.isfinite(value):
            return f"{name} {_show(value)} is not a finite number"
    if cell_m <= 0:
        return f"{names[2]} {cell_m:g} must be > 0"
    for name, value in zip(names[3:], (nx, ny)):
        if not _is_number(value) or not math.isfinite(value) or value != int(value) or value < 1:
            return f"{name} {_show(value)} must be a positive integer"
    return too_many_cells(nx, ny)


@dataclass(frozen=True)
class Grid:
    """The receiver grid: ``nx`` x ``ny`` square cells of ``cell_m``; ``(x0_m, y0_m)`` is the centre of cell (0, 0)."""

    x0_m: float
    y0_m: float
    cell_m: float
    nx: int
    ny: int

    def __post_init__(self) -> None:
        problem = grid_problem(self.x0_m, self.y0_m, self.cell_m, self.nx, self.ny)
        if problem:
            raise InvalidSettingError(
                f"invalid receiver grid: {problem}",
                hint=f"use a finite origin, a cell size > 0 and at most {MAX_CELLS:,} cells (larger or fewer cells)",
            )

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: arrays over the grid are indexed ``[iy, ix]`` (row-major, y outer)."""
        return (self.ny, self.nx)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            self.x0_m + self.cell_m * np.arange(self.nx, dtype=np.float64),
            self.y0_m + self.cell_m * np.arange(self.ny, dtype=np.float64),
        )

    def bounds(self) -> tuple[float, float, float, float]:
        """Outer edges ``(xmin, ymin, xmax, ymax)`` of the grid's cells."""
        h = self.cell_m / 2
        return (
            self.x0_m - h,
            self.y0_m - h,
            self.x0_m + (self.nx - 1) * self.cell_m + h,
            self.y0_m + (self.ny - 1) * self.cell_m + h,
        )

    def index_of(self, x: float, y: float) -> tuple[int, int]:
        """``(ix, iy)`` of the cell holding the point; a point on the grid's far edge belongs to the last cell."""
        fx, fy = (x - self.x0_m) / self.cell_m + 0.5, (y - self.y0_m) / self.cell_m + 0.5
        ix, iy = math.floor(fx), math.floor(fy)
        ix = self.nx - 1 if ix == self.nx and fx - self.nx < 1e-9 else ix
        iy = self.ny - 1 if iy == self.ny and fy - self.ny < 1e-9 else iy
        if not (0 <= ix < self.nx and 0 <= iy < self.ny) or not (math.isfinite(x) and math.isfinite(y)):
            xmin, ymin, xmax, ymax = self.bounds()
            raise InvalidCoordinatesError(
                f"point ({x}, {y}) is outside the grid [{xmin}, {xmax}] x [{ymin}, {ymax}] m",
                hint="use coordinates in the scene frame inside the grid",
            )
        return ix, iy

    def to_dict(self) -> dict[str, Any]:
        return {"x0_m": self.x0_m, "y0_m": self.y0_m, "cell_m": self.cell_m, "nx": self.nx, "ny": self.ny}

    @classmethod
    def from_meta(cls, grid: dict[str, Any]) -> Grid:
        """The grid recorded in a dataset's metadata (``meta["grid"]``, as written by :meth:`to_dict`)."""
        return cls(float(grid["x0_m"]), float(grid["y0_m"]), float(grid["cell_m"]), int(grid["nx"]), int(grid["ny"]))
