"""The per-cell table: the contract between ``dtradar_data`` and ``dtradar_rl`` (docs: Datasets, the per-cell table).

One row per grid cell, blocked cells included, in row-major order (``iy`` outer, ``ix`` inner), so a column
reshapes to ``[H, W] = [ny, nx]``. Column names carry their unit. Radio columns are null where a cell has no
propagation path (blocked cells always have none).

Angles follow Sionna: ``*_zen_rad`` is the **zenith** angle θ ∈ [0, π] measured from +z (not elevation);
``*_az_rad`` is the azimuth φ ∈ (-π, π] measured from +x towards +y. "Strongest" means the path with the largest
|a|² after the antenna-port reduction documented in :mod:`dtradar_data.rt.features`.

Changing a schema means bumping ``SCHEMA_VERSION`` and checking in a new golden file
(``dtradar_data/core/golden/cells_v{N}.json``); ``tests/data/test_schema.py`` enforces both.

A *moving* twin (:mod:`dtradar_data.core.dataset`: ``T`` snapshots in one table) has its own schemas,
:data:`MOVING_CELL_SCHEMA` and :data:`MOVING_PATH_SCHEMA`: the static ones plus an int32 ``t`` (snapshot index)
and, in the cell table, a bool ``mover`` (a mover covers the cell at ``t``). They are versioned on their own
(:data:`MOVING_SCHEMA_VERSION`, golden files ``moving_cells_v{N}.json`` and ``moving_paths_v{N}.json``) rather
than by a bump of ``SCHEMA_VERSION``: ``SCHEMA_VERSION`` is hashed into every dataset version, so a bump would
give every unchanged static build a new version. A moving table is always its static schema of the same
``SCHEMA_VERSION`` plus these columns; a change of the static columns bumps both.
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


#: The version of the per-path channel columns (``--rt.path-channels``): hashed into the versions of twins built with
#: them only (through the RT settings, :meth:`~dtradar_data.rt.settings.RTSettings.hashed`), so versions built without
#: them keep their hashes. Bump it, with a new golden file ``paths_channels_v{N}.json``, when these columns change.
CHANNEL_SCHEMA_VERSION = 1

#: The per-path channel columns, after the static ones: each path's polarimetric transfer matrix between unit-gain
#: isotropic ports and its interaction points (:mod:`dtradar_data.rt.polarimetric`, :mod:`dtradar_data.channels`).
_CHANNEL_PATH_FIELDS: list[tuple[str, pa.DataType, bool, str]] = [
    *(
        (
            f"pol_{r}{t}_{part}",
            pa.float32(),
            False,
            f"{'real' if part == 're' else 'imaginary'} part of the transfer from the transmitter's isotropic "
            f"{t.upper()} port to the receiver's isotropic {r.upper()} port (V = θ̂, H = φ̂ of the global spherical "
            "basis at the departure / arrival direction), baseband-equivalent as a_re/a_im",
        )
        for r in "vh"
        for t in "vh"
        for part in ("re", "im")
    ),
    (
        "vertices_m",
        pa.list_(pa.float32()),
        False,
        "interaction points in order, x, y, z of each (3 · depth values; empty for line of sight), scene frame, metres",
    ),
]
CHANNEL_PATH_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _CHANNEL_PATH_FIELDS)
CHANNEL_PATH_COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _CHANNEL_PATH_FIELDS}


def meta_path_channels(meta: dict) -> bool:
    """Whether a stored version's per-path table has the channel columns: its RT settings (``meta.json``'s ``rt``)
    name ``path_channels``; versions built before they existed do not."""
    return bool((meta.get("rt") or {}).get("path_channels"))


#: The version of the moving-twin schemas (static schema + ``t`` + ``mover``): bump it, with new golden files, when
#: the columns a moving twin adds change; hashed into moving twins' versions only.
MOVING_SCHEMA_VERSION = 1

_T_FIELD = ("t", pa.int32(), False, "snapshot index, 0-based: the world at time t · dt_s (meta moving.dt_s)")
_MOVING_CELL_FIELDS = [
    *_CELL_FIELDS,
    _T_FIELD,
    ("mover", pa.bool_(), False, "a mover (person, vehicle) covers the cell at snapshot t (then blocked is true too)"),
]
_MOVING_PATH_FIELDS = [*_PATH_FIELDS, _T_FIELD]


def _schema(fields: list[tuple[str, pa.DataType, bool, str]], kind: str, version: int = SCHEMA_VERSION) -> pa.Schema:
    metadata = {"dtradar.table": kind, "dtradar.schema_version": str(version)}
    if kind.startswith("moving"):  # the static schema it extends
        metadata["dtradar.static_schema_version"] = str(SCHEMA_VERSION)
    return pa.schema(
        [pa.field(n, t, nullable=nullable, metadata={"description": d}) for n, t, nullable, d in fields],
        metadata=metadata,
    )


CELL_SCHEMA: pa.Schema = _schema(_CELL_FIELDS, "cells")
PATH_SCHEMA: pa.Schema = _schema(_PATH_FIELDS, "paths")
#: A moving twin's per-cell table: :data:`CELL_SCHEMA` + ``t`` + ``mover``, rows sorted by ``(t, iy, ix)``.
MOVING_CELL_SCHEMA: pa.Schema = _schema(_MOVING_CELL_FIELDS, "moving-cells", MOVING_SCHEMA_VERSION)
#: A moving twin's per-path table: :data:`PATH_SCHEMA` + ``t``, rows sorted by ``(t, iy, ix, path)``.
MOVING_PATH_SCHEMA: pa.Schema = _schema(_MOVING_PATH_FIELDS, "moving-paths", MOVING_SCHEMA_VERSION)

CELL_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _CELL_FIELDS)
PATH_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _PATH_FIELDS)
#: Radio feature columns (float32, null where a cell has no path): what an agent may observe.
RADIO_COLUMNS: tuple[str, ...] = tuple(f[0] for f in _CELL_FIELDS if f[2])
COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _CELL_FIELDS}
PATH_COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _PATH_FIELDS}
MOVING_COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _MOVING_CELL_FIELDS}
MOVING_PATH_COLUMN_DESCRIPTIONS: dict[str, str] = {f[0]: f[3] for f in _MOVING_PATH_FIELDS}


#: The version of the several-transmitter extension (the ``tx{k}_`` columns and the per-path ``tx`` column): hashed
#: into the versions of twins with more than one transmitter only, so one-transmitter versions keep their hashes.
MULTI_TX_SCHEMA_VERSION = 1

#: The per-transmitter radio columns of the cell table: transmitter 0's keep their names, transmitter ``k >= 1``'s
#: are ``tx{k}_<name>`` (:func:`tx_column`).
TX_CELL_COLUMNS: tuple[str, ...] = ("num_paths", "los", *RADIO_COLUMNS)
_TX_FIELD = ("tx", pa.int16(), False, "index of the transmitter the path leaves (meta transmitters[tx]; 0 = the first)")


def tx_column(name: str, k: int) -> str:
    """The cell-table column of radio feature ``name`` for transmitter ``k`` (``name`` itself for ``k = 0``)."""
    return name if k == 0 else f"tx{k}_{name}"


def _tx_fields(fields, transmitters: int):
    """``fields`` plus, for transmitters 1..K-1, their copies of the radio fields (``tx{k}_`` names)."""
    by_name = {f[0]: f for f in fields}
    extra = []
    for k in range(1, transmitters):
        for name in TX_CELL_COLUMNS:
            _, typ, nullable, desc = by_name[name]
            extra.append((tx_column(name, k), typ, nullable, f"transmitter {k}: {desc}"))
    return [*fields, *extra]


def _with_transmitters(schema: pa.Schema, transmitters: int) -> pa.Schema:
    meta = dict(schema.metadata or {})
    meta[b"dtradar.transmitters"] = str(transmitters).encode()
    meta[b"dtradar.multi_tx_schema_version"] = str(MULTI_TX_SCHEMA_VERSION).encode()
    return schema.with_metadata(meta)


def meta_transmitters(meta: dict) -> int:
    """K, the transmitters of a stored version, from its ``meta.json``: the ``transmitters`` list (written only when
    a twin has several), else 1."""
    listed = meta.get("transmitters")
    return len(listed) if isinstance(listed, list) and listed else 1


def check_transmitters(transmitters) -> int:
    if isinstance(transmitters, bool) or not isinstance(transmitters, int) or transmitters < 1:
        raise ValueError(f"a twin has 1 or more transmitters, got {transmitters!r}")
    return transmitters


def cell_schema(moving: bool, transmitters: int = 1) -> pa.Schema:
    """The per-cell schema of a static twin, or of a moving one; with ``transmitters`` K > 1 (static twins only) the
    radio columns of transmitters 1..K-1 follow the static columns (:func:`tx_column`)."""
    if check_transmitters(transmitters) == 1:
        return MOVING_CELL_SCHEMA if moving else CELL_SCHEMA
    if moving:
        raise ValueError("a moving twin has one transmitter in this version")
    schema = _schema(_tx_fields(_CELL_FIELDS, transmitters), "cells")
    return _with_transmitters(schema, transmitters)


def path_schema(moving: bool, transmitters: int = 1, channels: bool = False) -> pa.Schema:
    """The per-path schema of a static twin, or of a moving one; with K > 1 transmitters an int16 ``tx`` column
    precedes ``path`` (rows sorted by ``(iy, ix, tx, path)``); with ``channels`` (static twins only) the channel
    columns follow (:data:`CHANNEL_PATH_COLUMNS`)."""
    if channels:
        if moving:
            raise ValueError("a moving twin stores no channel columns in this version")
        base = path_schema(False, transmitters)
        fields = [(f.name, f.type, f.nullable, f.metadata[b"description"].decode()) for f in base]
        schema = _schema([*fields, *_CHANNEL_PATH_FIELDS], "paths")
        meta = {**(base.metadata or {}), b"dtradar.channel_schema_version": str(CHANNEL_SCHEMA_VERSION).encode()}
        return schema.with_metadata(meta)
    if check_transmitters(transmitters) == 1:
        return MOVING_PATH_SCHEMA if moving else PATH_SCHEMA
    if moving:
        raise ValueError("a moving twin has one transmitter in this version")
    fields = list(_PATH_FIELDS)
    fields.insert(2, _TX_FIELD)
    return _with_transmitters(_schema(fields, "paths"), transmitters)


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
