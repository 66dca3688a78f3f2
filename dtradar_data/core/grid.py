"""The receiver grid: square cells over the scene's floor, indexed ``[iy, ix]`` (row-major, y outer).

One class for the grid of a scene description and the grid recorded in a stored dataset's metadata.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.errors import InvalidCoordinatesError


@dataclass(frozen=True)
class Grid:
    """The receiver grid: ``nx`` x ``ny`` square cells of ``cell_m``; ``(x0_m, y0_m)`` is the centre of cell (0, 0)."""

    x0_m: float
    y0_m: float
    cell_m: float
    nx: int
    ny: int

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
