"""From traced paths to the per-cell features of the table (:mod:`dtradar_data.core.schema`), in plain numpy.

The antenna-port reduction (written into every dataset card):

* **path power** ``g_p`` = ``|a_p|²`` averaged over all (RX port, TX port) pairs, i.e. ‖H_p‖²_F / (N_r·N_t). With the
  paper's 8×2 dual-polarised TR 38.901 array and a vertical dipole this is the array-averaged gain; the cross-polar
  ports make it ≈3 dB lower than the co-polar gain alone.
* **strongest path** = the valid path with the largest ``g_p``. Its delay and four angles come from Sionna
  (synthetic array: geometry of the array centre).
* **a_re, a_im, phase_rad** = the baseband-equivalent complex coefficient ``a·exp(-j2π f_c τ)`` of the strongest
  path at the reference port pair (RX port 0, TX port 0: first element, first polarisation), and its angle. Sionna's
  ``Paths.a`` is the passband coefficient without the carrier phase; ``Paths.cir()`` applies the same factor, and it
  is what a receiver at the cell would measure, so the phase carries the propagation delay as in the paper.
* **path_gain_db** = ``10·log10(Σ_p g_p)`` over all valid paths (incoherent sum).
* **delay_spread_s** = power-weighted RMS delay spread ``sqrt(Σ g τ² / Σ g − (Σ g τ / Σ g)²)``.
* **los** = the strongest path has no interaction.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from dtradar_data.core.schema import cell_schema, path_schema, tx_column

# Sionna InteractionType codes -> one letter each (the per-path table's `interactions` column).
INTERACTION_LETTERS = {1: "S", 2: "D", 4: "R", 8: "F"}

CELL_RADIO_KEYS = (
    "num_paths",
    "los",
    "path_gain_db",
    "a_re",
    "a_im",
    "phase_rad",
    "tau_s",
    "aod_zen_rad",
    "aod_az_rad",
    "aoa_zen_rad",
    "aoa_az_rad",
    "delay_spread_s",
)


def reduce_cells(batch) -> dict[str, np.ndarray]:
    """Per-receiver features of a :class:`~dtradar_data.rt.tracer.PathBatch` (NaN where a receiver has no path)."""
    if batch.valid.shape[1] == 0:  # no receiver of the batch has a path (a far city corner): Sionna gives P = 0
        batch = _one_empty_path(batch)
    valid = batch.valid
    n = valid.shape[0]
    gain = np.where(valid, batch.gain, 0.0)
    num_paths = valid.sum(axis=1)
    has = num_paths > 0
    best = np.argmax(np.where(valid, batch.gain, -1.0), axis=1)
    rows = np.arange(n)

    def pick(x):
        return np.where(has, x[rows, best], np.nan)

    total = gain.sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        path_gain_db = np.where(has, 10.0 * np.log10(total), np.nan)
        tau = np.where(valid, batch.tau, 0.0)
        mean_tau = (gain * tau).sum(axis=1) / total
        var = (gain * tau**2).sum(axis=1) / total - mean_tau**2
    delay_spread = np.where(has, np.sqrt(np.clip(var, 0.0, None)), np.nan)
    a = batch.a[rows, best] * np.exp(-2j * np.pi * batch.frequency_hz * np.where(has, batch.tau[rows, best], 0.0))
    depth = (batch.interactions != 0).sum(axis=0)  # [N, P]
    return {
        "num_paths": num_paths.astype(np.int16),
        "los": has & (depth[rows, best] == 0),
        "path_gain_db": path_gain_db,
        "a_re": np.where(has, a.real, np.nan),
        "a_im": np.where(has, a.imag, np.nan),
        "phase_rad": np.where(has, np.angle(a), np.nan),
        "tau_s": pick(batch.tau),
        "aod_zen_rad": pick(batch.theta_t),
        "aod_az_rad": pick(batch.phi_t),
        "aoa_zen_rad": pick(batch.theta_r),
        "aoa_az_rad": pick(batch.phi_r),
        "delay_spread_s": delay_spread,
    }


def _one_empty_path(batch):
    """The batch padded to one invalid path per receiver, so that per-receiver reductions have a slot to look at."""
    import dataclasses

    pad = {
        f.name: np.zeros((*getattr(batch, f.name).shape[:-1], 1), dtype=getattr(batch, f.name).dtype)
        for f in dataclasses.fields(batch)
        if isinstance(getattr(batch, f.name), np.ndarray)
    }
    return dataclasses.replace(batch, **pad)


def path_rows(batch, ix: np.ndarray, iy: np.ndarray) -> dict[str, np.ndarray]:
    """Every valid path of every receiver, strongest first within a cell (columns of ``PATH_SCHEMA``)."""
    valid = batch.valid
    order = np.argsort(-np.where(valid, batch.gain, -1.0), axis=1, kind="stable")
    r, k = np.nonzero(np.take_along_axis(valid, order, axis=1))
    p = order[r, k]
    inter = batch.interactions[:, r, p].T  # [M, D]
    depth = (inter != 0).sum(axis=1)
    letters = ["-".join(INTERACTION_LETTERS.get(int(c), "?") for c in row if c) for row in inter]
    a = batch.a[r, p] * np.exp(-2j * np.pi * batch.frequency_hz * batch.tau[r, p])
    with np.errstate(divide="ignore"):
        power_db = 10.0 * np.log10(batch.gain[r, p])
    rows = {  # a: baseband-equivalent, as in reduce_cells
        "ix": np.asarray(ix)[r].astype(np.int32),
        "iy": np.asarray(iy)[r].astype(np.int32),
        "path": k.astype(np.int16),
        "a_re": a.real,
        "a_im": a.imag,
        "power_db": power_db,
        "tau_s": batch.tau[r, p],
        "aod_zen_rad": batch.theta_t[r, p],
        "aod_az_rad": batch.phi_t[r, p],
        "aoa_zen_rad": batch.theta_r[r, p],
        "aoa_az_rad": batch.phi_r[r, p],
        "depth": depth.astype(np.int8),
        "interactions": np.array(letters, dtype=object),
    }
    if batch.transfer is not None:  # --rt.path-channels: the channel columns (schema.CHANNEL_PATH_COLUMNS)
        rows.update(_channel_rows(batch, r, p, depth))
    return rows


def _channel_rows(batch, r: np.ndarray, p: np.ndarray, depth: np.ndarray) -> dict[str, np.ndarray]:
    """The transfer matrices (baseband-equivalent, as ``a``) and interaction points of the paths ``(r, p)``."""
    carrier = np.exp(-2j * np.pi * batch.frequency_hz * batch.tau[r, p])
    out = {}
    for i, rx in enumerate("vh"):
        for j, tx in enumerate("vh"):
            t = batch.transfer[i, j, r, p] * carrier
            out[f"pol_{rx}{tx}_re"], out[f"pol_{rx}{tx}_im"] = t.real, t.imag
    points = batch.vertices[:, :, r, p].transpose(2, 0, 1)  # [M, D, 3]
    vertices = np.empty(len(r), dtype=object)
    vertices[:] = [pts[:d].ravel() for pts, d in zip(points, depth)]
    out["vertices_m"] = vertices
    return out


def radio_keys(transmitters: int = 1) -> tuple[str, ...]:
    """The radio keys of a cell table with ``transmitters`` transmitters (``tx{k}_`` for k >= 1)."""
    return tuple(tx_column(key, k) for k in range(transmitters) for key in CELL_RADIO_KEYS)


def cells_table(
    xs: np.ndarray, ys: np.ndarray, blocked: np.ndarray, free_features: dict[str, np.ndarray], transmitters: int = 1
) -> pa.Table:
    """Assemble the full per-cell table: ``blocked`` is ``bool[ny, nx]``; ``free_features`` holds one value per free
    cell in row-major order (from :func:`reduce_cells`; transmitter k's under ``tx{k}_`` keys). Blocked cells get no
    paths and null radio columns."""
    schema = cell_schema(False, transmitters)
    ny, nx = blocked.shape
    iy, ix = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    x, y = np.meshgrid(xs, ys, indexing="xy")
    free = ~blocked.ravel()
    n = blocked.size
    cols: dict[str, pa.Array] = {
        "ix": pa.array(ix.ravel(), pa.int32()),
        "iy": pa.array(iy.ravel(), pa.int32()),
        "x_m": pa.array(x.ravel(), pa.float64()),
        "y_m": pa.array(y.ravel(), pa.float64()),
        "blocked": pa.array(blocked.ravel()),
    }
    for key in radio_keys(transmitters):
        src = np.asarray(free_features[key])
        if src.shape[0] != free.sum():
            raise ValueError(f"feature {key!r} has {src.shape[0]} values for {int(free.sum())} free cells")
        field = schema.field(key)  # num_paths (int16) and los (bool) of every transmitter are not null
        if pa.types.is_integer(field.type):
            full = np.zeros(n, np.int16)
            full[free] = src
            cols[key] = pa.array(full, pa.int16())
        elif pa.types.is_boolean(field.type):
            full = np.zeros(n, bool)
            full[free] = src
            cols[key] = pa.array(full)
        else:
            full = np.full(n, np.nan, np.float32)
            full[free] = src
            cols[key] = pa.array(full, field.type, mask=np.isnan(full))
    return pa.Table.from_pydict(cols, schema=schema)


def paths_table(rows: list[dict[str, np.ndarray]], transmitters: int = 1) -> pa.Table:
    """Concatenate :func:`path_rows` outputs into a ``PATH_SCHEMA`` table, sorted by (iy, ix, path); with several
    transmitters (rows with a ``tx`` key) by (iy, ix, tx, path)."""
    channels = any("vertices_m" in r for r in rows)  # traced with --rt.path-channels
    schema = path_schema(False, transmitters, channels)
    cols = {}
    for f in schema:
        listed = f.name in ("interactions", "vertices_m")  # object arrays: one string / float array per path
        parts = [r[f.name] for r in rows]
        values = np.concatenate(parts) if parts else np.array([], dtype=object if listed else None)
        cols[f.name] = pa.array(values.tolist() if listed else values, f.type)
    table = pa.Table.from_pydict(cols, schema=schema)
    keys = ["iy", "ix", "path"] if transmitters == 1 else ["iy", "ix", "tx", "path"]
    return table.sort_by([(k, "ascending") for k in keys])
