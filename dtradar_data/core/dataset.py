"""A loaded dataset: one version of one ``scene/variant`` per-cell table, plus its metadata.

The object is a read-only view; building and storing live in :mod:`dtradar_data.pipeline` and
:mod:`dtradar_data.store`. ``Dataset.from_table`` wraps an in-memory table (tests, synthetic data) the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa

from dtradar_data.core.grid import Grid
from dtradar_data.core.schema import RADIO_COLUMNS

#: The grid of a stored dataset is the scene's receiver grid (``meta["grid"]``); one class for both.
GridInfo = Grid


@dataclass(frozen=True)
class Dataset:
    """One dataset version. ``table`` rows are in row-major order (``iy`` outer, ``ix`` inner)."""

    name: str
    table: pa.Table
    meta: dict[str, Any]
    version: str | None = None
    path: Path | None = None
    paths_table: pa.Table | None = field(default=None, repr=False)

    @classmethod
    def from_table(cls, table: pa.Table, meta: dict[str, Any], name: str = "memory/synthetic") -> Dataset:
        table = table.sort_by([("iy", "ascending"), ("ix", "ascending")])
        return cls(name=name, table=table, meta=meta, version=meta.get("version"))

    @property
    def frame(self) -> pl.DataFrame:
        """The per-cell table as a polars DataFrame (zero-copy from Arrow where possible)."""
        return pl.from_arrow(self.table)

    @property
    def grid_info(self) -> GridInfo:
        return GridInfo.from_meta(self.meta["grid"])

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid_info.shape

    @property
    def blocked(self) -> np.ndarray:
        """``bool[H, W]``: True where an obstacle occupies the cell."""
        return self.table.column("blocked").to_numpy(zero_copy_only=False).reshape(self.shape)

    def grid(self, columns: tuple[str, ...] | list[str] = RADIO_COLUMNS, fill: float = np.nan) -> np.ndarray:
        """``float32[H, W, F]`` of the given columns; nulls (no path, blocked) become ``fill``."""
        h, w = self.shape
        out = np.empty((h, w, len(columns)), dtype=np.float32)
        for k, name in enumerate(columns):
            col = self.table.column(name).cast(pa.float32()).fill_null(fill)
            out[..., k] = col.to_numpy(zero_copy_only=False).reshape(h, w)
        return out

    def __repr__(self) -> str:
        h, w = self.shape
        return f"Dataset({self.name!r}, version={self.version!r}, grid={w}x{h}, rows={self.table.num_rows})"
