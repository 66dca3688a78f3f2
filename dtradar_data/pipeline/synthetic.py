"""Tiny synthetic per-cell tables that follow the contract, for tests and examples without a ray tracer.

The radio features are those of a single line-of-sight path in free space from a transmitter at ``tx``
(Friis gain, delay = distance / c, geometric angles), so they are physically consistent, smooth and unique per cell.

:func:`synthetic_moving_dataset` is a *moving* twin (the format is in :mod:`dtradar_data.core.dataset`): the same
static twin with a few 1-cell :class:`Mover` s walking back and forth along rows or columns, one snapshot per step of
the movers. A mover's cell is blocked at that snapshot (``mover`` true) and its radio features are null there; every
other cell keeps the static twin's features (a real re-traced twin would also change the features around a mover).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from dtradar_data.core.dataset import Dataset, GridInfo
from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_data.core.schema import CELL_SCHEMA, SCHEMA_VERSION, TX_CELL_COLUMNS, cell_schema, tx_column

#: The two columns a moving twin adds to the per-cell table (see :mod:`dtradar_data.core.dataset`).
MOVING_FIELDS = (pa.field("t", pa.int32(), nullable=False), pa.field("mover", pa.bool_(), nullable=False))

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


def synthetic_multi_tx_dataset(
    nx: int = 8,
    ny: int = 6,
    blocked: np.ndarray | None = None,
    *,
    txs: tuple[tuple[float, float, float], ...] = ((0.3, 0.2, 3.0), (3.7, 2.8, 3.0)),
    heard: np.ndarray | None = None,
    cell_m: float = 0.5,
    name: str = "synthetic-tx/blueprint",
    **kwargs,
) -> Dataset:
    """A twin with ``len(txs)`` transmitters (:func:`~dtradar_data.core.schema.cell_schema` with K > 1): each
    transmitter's columns as :func:`synthetic_table` computes them for it, nulled (no path, ``num_paths`` 0) where
    ``heard[k]`` (``bool[K, ny, nx]``, default everywhere) is False: the cells transmitter ``k`` does not reach."""
    blocked = np.zeros((ny, nx), bool) if blocked is None else np.asarray(blocked, bool)
    heard = np.ones((len(txs), ny, nx), bool) if heard is None else np.asarray(heard, bool)
    cols: dict[str, pa.Array] = {}
    for k, tx in enumerate(txs):
        part = synthetic_table(nx, ny, blocked | ~heard[k], cell_m=cell_m, tx=tx, **kwargs)
        if k == 0:
            cols.update({c: part.column(c) for c in ("ix", "iy", "x_m", "y_m")})
            cols["blocked"] = pa.array(blocked.ravel())
        for c in TX_CELL_COLUMNS:
            cols[tx_column(c, k)] = part.column(c)
    schema = cell_schema(False, len(txs))
    table = pa.Table.from_arrays([cols[f.name] for f in schema], schema=schema)
    grid = GridInfo(x0_m=0.5 * cell_m, y0_m=0.5 * cell_m, cell_m=cell_m, nx=nx, ny=ny)
    meta = {
        "name": name,
        "schema_version": SCHEMA_VERSION,
        "grid": grid.to_dict(),
        "synthetic": True,
        "transmitters": [{"name": f"tx{k}", "position_m": list(tx)} for k, tx in enumerate(txs)],
    }
    return Dataset.from_table(table, meta, name=name)


# -- moving twins ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mover:
    """A 1-cell mover walking back and forth along a row (``axis="x"``) or a column (``"y"``): from ``start`` to
    ``length - 1`` cells further along the axis and back, one cell per snapshot (period ``2 * (length - 1)``; a
    mover of length 1 stands still)."""

    name: str
    start: tuple[int, int]
    axis: str = "x"
    length: int = 3

    def __post_init__(self) -> None:
        if self.axis not in ("x", "y") or self.length < 1:
            raise InvalidCoordinatesError(
                f"mover {self.name!r}: axis must be 'x' or 'y' and length >= 1, got {self.axis!r} and {self.length}"
            )

    @property
    def period(self) -> int:
        return max(1, 2 * (self.length - 1))

    def cell(self, k: int) -> tuple[int, int]:
        """``(ix, iy)`` at snapshot ``k``."""
        p = k % self.period
        off = p if p < self.length else self.period - p
        ix, iy = self.start
        return (ix + off, iy) if self.axis == "x" else (ix, iy + off)


def default_movers(blocked: np.ndarray, count: int = 3, max_length: int = 4) -> list[Mover]:
    """``count`` deterministic movers on free segments of ``blocked`` (``bool[ny, nx]``): each walks up to
    ``max_length`` cells of the longest free run of a row or column (rows ``ny/2``, ``3ny/4``, ``ny/4``, columns
    ``nx/3``, ``2nx/3``, tried in turn) whose every cell has a free cell beside it (a robot can step aside, so no
    mover plugs a one-cell-wide corridor for good), lengths alternating ``max_length`` and ``max_length - 1``."""
    ny, nx = blocked.shape
    open_ = np.pad(~blocked, 1, constant_values=False)
    side_x = open_[:-2, 1:-1] | open_[2:, 1:-1]  # a free cell above or below (beside a row-walker)
    side_y = open_[1:-1, :-2] | open_[1:-1, 2:]  # a free cell left or right (beside a column-walker)
    lines = [("x", ny // 2), ("y", nx // 3), ("x", (3 * ny) // 4), ("y", (2 * nx) // 3), ("x", ny // 4)]
    movers: list[Mover] = []
    seen = set()
    for axis, at in lines:
        if len(movers) == count or (axis, at) in seen:
            continue
        seen.add((axis, at))
        free = (~blocked[at, :] & side_x[at, :]) if axis == "x" else (~blocked[:, at] & side_y[:, at])
        best, run_start, best_start = 0, 0, 0
        for i, f in enumerate(list(free) + [False]):
            if not f:
                if i - run_start > best:
                    best, best_start = i - run_start, run_start
                run_start = i + 1
        length = min(best, max_length - (len(movers) % 2), max_length)
        if length < 2:
            continue
        first = best_start + (best - length) // 2  # centred in the run
        start = (first, at) if axis == "x" else (at, first)
        movers.append(Mover(f"walker-{len(movers)}", start, axis, length))
    return movers


def synthetic_moving_dataset(
    nx: int = 8,
    ny: int = 6,
    snapshots: int | None = None,
    movers: list[Mover] | None = None,
    blocked: np.ndarray | None = None,
    *,
    dt_s: float = 1.0,
    cell_m: float = 0.5,
    name: str = "synthetic-moving/blueprint",
    **kwargs,
) -> Dataset:
    """A moving twin: :func:`synthetic_table` with ``blocked`` as its static obstacles, plus ``movers`` (default
    :func:`default_movers`), over ``snapshots`` snapshots ``dt_s`` apart (default: the least common multiple of the
    movers' periods, so every mover loops seamlessly; with another count a mover jumps back at the wrap)."""
    static = np.zeros((ny, nx), bool) if blocked is None else np.asarray(blocked, bool)
    if static.shape != (ny, nx):
        raise ValueError(f"blocked has shape {static.shape}, expected (ny, nx) = {(ny, nx)}")
    movers = default_movers(static) if movers is None else list(movers)
    if snapshots is None:
        snapshots = math.lcm(*(m.period for m in movers)) if movers else 1
    if isinstance(snapshots, bool) or int(snapshots) != snapshots or snapshots < 1:
        raise InvalidCoordinatesError(f"snapshots must be a positive int, got {snapshots!r}")
    snapshots = int(snapshots)
    occupied = np.zeros((snapshots, ny, nx), bool)
    for m in movers:
        for k in range(snapshots):
            ix, iy = m.cell(k)
            if not (0 <= ix < nx and 0 <= iy < ny) or static[iy, ix]:
                raise InvalidCoordinatesError(
                    f"mover {m.name!r} is on ({ix}, {iy}) at snapshot {k}: off the {nx} x {ny} grid or on an obstacle",
                    hint="movers walk on free cells",
                )
            occupied[k, iy, ix] = True
    parts = []
    for k in range(snapshots):
        table = synthetic_table(nx, ny, static | occupied[k], cell_m=cell_m, **kwargs)
        table = table.append_column(MOVING_FIELDS[0], pa.array(np.full(nx * ny, k, np.int32), pa.int32()))
        parts.append(table.append_column(MOVING_FIELDS[1], pa.array(occupied[k].ravel())))
    grid = GridInfo(x0_m=0.5 * cell_m, y0_m=0.5 * cell_m, cell_m=cell_m, nx=nx, ny=ny)
    meta = {
        "name": name,
        "schema_version": SCHEMA_VERSION,
        "grid": grid.to_dict(),
        "synthetic": True,
        "moving": {"snapshots": snapshots, "dt_s": float(dt_s), "movers": [m.name for m in movers]},
        "synthetic_movers": [
            {"name": m.name, "start": list(m.start), "axis": m.axis, "length": m.length} for m in movers
        ],
    }
    return Dataset.from_table(pa.concat_tables(parts), meta, name=name)
