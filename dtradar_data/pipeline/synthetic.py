"""Tiny synthetic per-cell tables that follow the contract, for tests and examples without a ray tracer.

The radio features are those of a single line-of-sight path in free space from a transmitter at ``tx``
(Friis gain, delay = distance / c, geometric angles), so they are physically consistent, smooth and unique per cell.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from dtradar_data.core.dataset import Dataset, GridInfo
from dtradar_data.core.schema import CELL_SCHEMA, SCHEMA_VERSION

C = 299_792_458.0


def synthetic_table(
    nx: int = 8,
    ny: int = 6,
    blocked: np.ndarray | None = None,
    *,
    cell_m: float = 0.5,
    tx: tuple[float, float, float] = (0.3, 0.2, 3.0),
    rx_height_m: float = 1.0,
    frequency_hz: float = 2.4e9,
) -> pa.Table:
    """A ``CELL_SCHEMA`` table for an ``nx × ny`` grid; ``blocked`` is ``bool[ny, nx]`` (default: none)."""
    blocked = np.zeros((ny, nx), bool) if blocked is None else np.asarray(blocked, bool)
    if blocked.shape != (ny, nx):
        raise ValueError(f"blocked has shape {blocked.shape}, expected (ny, nx) = {(ny, nx)}")
    iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    x, y = (ix + 0.5) * cell_m, (iy + 0.5) * cell_m
    d = np.stack([x - tx[0], y - tx[1], np.full_like(x, rx_height_m - tx[2])], -1)
    r = np.linalg.norm(d, axis=-1)
    lam = C / frequency_hz
    amp = lam / (4 * np.pi * r)
    tau = r / C
    phase = np.angle(np.exp(-2j * np.pi * frequency_hz * tau))
    a = amp * np.exp(1j * phase)
    zen_t = np.arccos(d[..., 2] / r)
    az_t = np.arctan2(d[..., 1], d[..., 0])
    zen_r, az_r = np.pi - zen_t, np.arctan2(-d[..., 1], -d[..., 0])
    free = ~blocked

    def col(v):
        return pa.array(np.where(free, v, np.nan).astype(np.float32).ravel(), pa.float32(), mask=blocked.ravel())

    arrays = {
        "ix": pa.array(ix.ravel(), pa.int32()),
        "iy": pa.array(iy.ravel(), pa.int32()),
        "x_m": pa.array(x.ravel(), pa.float64()),
        "y_m": pa.array(y.ravel(), pa.float64()),
        "blocked": pa.array(blocked.ravel()),
        "num_paths": pa.array(free.astype(np.int16).ravel(), pa.int16()),
        "los": pa.array(free.ravel()),
        "path_gain_db": col(20 * np.log10(amp)),
        "a_re": col(a.real),
        "a_im": col(a.imag),
        "phase_rad": col(phase),
        "tau_s": col(tau),
        "aod_zen_rad": col(zen_t),
        "aod_az_rad": col(az_t),
        "aoa_zen_rad": col(zen_r),
        "aoa_az_rad": col(az_r),
        "delay_spread_s": col(np.zeros_like(r)),
    }
    return pa.Table.from_pydict(arrays, schema=CELL_SCHEMA)


def synthetic_dataset(
    nx: int = 8,
    ny: int = 6,
    blocked: np.ndarray | None = None,
    *,
    cell_m: float = 0.5,
    name: str = "synthetic/blueprint",
    **kwargs,
) -> Dataset:
    """A :class:`Dataset` around :func:`synthetic_table`, with the metadata a real dataset carries."""
    table = synthetic_table(nx, ny, blocked, cell_m=cell_m, **kwargs)
    grid = GridInfo(x0_m=0.5 * cell_m, y0_m=0.5 * cell_m, cell_m=cell_m, nx=nx, ny=ny)
    meta = {"name": name, "schema_version": SCHEMA_VERSION, "grid": grid.to_dict(), "synthetic": True}
    return Dataset.from_table(table, meta, name=name)
