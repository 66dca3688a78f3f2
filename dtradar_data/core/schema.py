"""The per-cell table: the contract between ``dtradar_data`` and ``dtradar_rl`` (DESIGN.md §3).

One row per grid cell, blocked cells included, in row-major order (``iy`` outer, ``ix`` inner), so a column
reshapes to ``[H, W] = [ny, nx]``. Column names carry their unit. Radio columns are null where a cell has no
propagation path (blocked cells always have none).

Angles follow Sionna: ``*_zen_rad`` is the **zenith** angle θ ∈ [0, π] measured from +z (not elevation);
``*_az_rad`` is the azimuth φ ∈ (-π, π] measured from +x towards +y. "Strongest" means the path with the largest
|a|² after the antenna-port reduction documented in :mod:`dtradar_data.rt.features`.

Changing a schema means bumping ``SCHEMA_VERSION`` and checking in a new golden file
(``dtradar_data/core/golden/cells_v{N}.json``); ``tests/data/test_schema.py`` enforces both.
"""

from __future__ import annotations

import json

import pyarrow as pa

SCHEMA_VERSION = 1

_CELL_FIELDS: list[tuple[str, pa.DataType, bool, str]] = [
    # name, type, nullable, description (written into the Parquet field metadata and the card)
    ("ix", pa.int32(), False, "grid column index, 0-based, along +x"),
    ("iy", pa.int32(), False, "grid row index, 0-based, along +y"),
    ("x_m", pa.float64(), False, "cell centre x in the scene frame, metres"),
    ("y_m", pa.float64(), False, "cell centre y in the scene frame, metres"),
    ("blocked", pa.bool_(), False, "an obstacle or building occupies the cell at robot height"),
    ("num_paths", pa.int16(), False, "number of valid propagation paths (0 where none or blocked)"),
    ("los", pa.bool_(), False, "the strongest path is the line-of-sight path"),
    ("path_gain_db", pa.float32(), True, "total received power gain over all paths, 10·log10(Σ|a|²), dB"),
    ("a_re", pa.float32(), True, "real part of the strongest path's complex coefficient"),
    ("a_im", pa.float32(), True, "imaginary part of the strongest path's complex coefficient"),
    ("phase_rad", pa.float32(), True, "phase of the strongest path's coefficient, radians in (-π, π]"),
    ("tau_s", pa.float32(), True, "propagation delay of the strongest path, seconds"),
    ("aod_zen_rad", pa.float32(), True, "zenith angle of departure of the strongest path (θ_t, from +z), rad"),
    ("aod_az_rad", pa.float32(), True, "azimuth angle of departure of the strongest path (φ_t, from +x), rad"),
    ("aoa_zen_rad", pa.float32(), True, "zenith angle of arrival of the strongest path (θ_r, from +z), rad"),
    ("aoa_az_rad", pa.float32(), True, "azimuth angle of arrival of the strongest path (φ_r, from +x), rad"),
    ("delay_spread_s", pa.float32(), True, "power-weighted RMS delay spread over all valid paths, seconds"),
]

_PATH_FIELDS: list[tuple[str, pa.DataType, bool, str]] = [
    ("ix", pa.int32(), False, "grid column index of the receiving cell"),
    ("iy", pa.int32(), False, "grid row index of the receiving cell"),
    ("path", pa.int16(), False, "path index within the cell, by decreasing power (0 = strongest)"),
    ("a_re", pa.float32(), False, "real part of the path coefficient"),
    ("a_im", pa.float32(), False, "imaginary part of the path coefficient"),
    ("power_db", pa.float32(), False, "path power gain 10·log10|a|², dB"),
    ("tau_s", pa.float32(), False, "propagation delay, seconds"),
    ("aod_zen_rad", pa.float32(), False, "zenith angle of departure, rad"),
    ("aod_az_rad", pa.float32(), False, "azimuth angle of departure, rad"),
    ("aoa_zen_rad", pa.float32(), False, "zenith angle of arrival, rad"),
    ("aoa_az_rad", pa.float32(), False, "azimuth angle of arrival, rad"),
    ("depth", pa.int8(), False, "number of interactions (0 = line of sight)"),
    (
        "interactions",
        pa.string(),
        False,
        "interaction types in order: S specular, D diffuse, R refraction, F diffraction; empty for line of sight",
    ),
]


def _schema(fields: list[tuple[str, pa.DataType, bool, str]], kind: str) -> pa.Schema:
    return pa.schema(
        [pa.field(n, t, nullable=nullable, metadata={"description": d}) for n, t, nullable, d in fields],
        metadata={"dtradar.table": kind, "dtradar.schema_version": str(SCHEMA_VERSION)},
    )


CELL_SCHEMA: pa.Schema = _schema(_CELL_FIELDS, "cells")
PATH_SCHEMA: pa.Schema = _schema(_PATH_FIELDS, "paths")

CELL_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _CELL_FIELDS)
PATH_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _PATH_FIELDS)
#: Radio feature columns (float32, null where a cell has no path): what an agent may observe.
RADIO_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _CELL_FIELDS if f[2])
COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _CELL_FIELDS}
PATH_COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _PATH_FIELDS}


def schema_to_json(schema: pa.Schema) -> str:
    """A stable, diffable JSON rendering of a schema (names, types, nullability, descriptions)."""
    fields = [
        {
            "name": f.name,
            "type": str(f.type),
            "nullable": f.nullable,
            "description": (f.metadata or {}).get(b"description", b"").decode(),
        }
        for f in schema
    ]
    meta = {k.decode(): v.decode() for k, v in (schema.metadata or {}).items()}
    return json.dumps({"metadata": meta, "fields": fields}, indent=2, ensure_ascii=False) + "\n"
