"""Where a scene's transmitters may stand: one or more per scene file, and never inside anything the scene holds.

A transmitter inside a metal cubicle or a building traces without error and gives a table in which most cells hear
nothing, which is worse than a refusal: the dataset looks valid. So every reader refuses it when the scene is named,
before any mesh is written or ray traced:

- :func:`check_transmitter_tables`: a file's ``tx`` is one ``[tx]`` table or an array of ``[[tx]]`` tables (a
  deployment with several access points or base stations; the first is transmitter 0). ``tx = []``, an entry that is
  not a table and two transmitters of one name are refused; :func:`tx_tables` lists them.
- :func:`check_one_array`: every transmitter has transmitter 0's array (rows, columns, pattern, polarization):
  Sionna gives a scene one transmitter array, so a file whose ``[[tx]]`` differ cannot be traced as written.
- :func:`object_at` / :func:`check_transmitter_clear`: no transmitter is in one of the spec's boxes (objects,
  walls, floor, ceiling) or prisms (a city's buildings), in every variant (a dynamic change can move an object onto
  it). The shapes of an XML scene's own mesh are checked by
  :func:`~dtradar_data.geometry.xml_meshes.check_transmitter_in_mesh` when that scene is built, since reading its
  meshes is not cheap.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.model import SceneSpec

__all__ = [
    "check_one_array",
    "check_transmitter_clear",
    "check_transmitter_tables",
    "object_at",
    "tx_label",
    "tx_tables",
]

#: The most transmitters one twin holds: each adds 14 columns to the cell table and its rays to every trace.
MAX_TRANSMITTERS = 16


def check_transmitter_tables(data: dict[str, Any], origin: str, *, section: str = "tx") -> None:
    """:class:`SceneFileError` unless the parsed TOML's ``section`` is absent (the reader names it missing), one table,
    or a non-empty array of tables with distinct names, at most :data:`MAX_TRANSMITTERS`."""
    value = data.get(section)
    if not isinstance(value, list):
        return
    if not value:
        raise SceneFileError(
            f"{origin}: {section} = [] holds no transmitter: a scene needs one",
            hint=f"write a [{section}] table, or one [[{section}]] table per transmitter",
        )
    bad = [k for k, t in enumerate(value) if not isinstance(t, dict)]
    if bad:
        raise SceneFileError(
            f"{origin}: {section}[{bad[0]}] is {value[bad[0]]!r}, not a table",
            hint=f"write each transmitter as a [[{section}]] table with position_m = [x, y, z]",
        )
    if len(value) > MAX_TRANSMITTERS:
        raise SceneFileError(
            f"{origin}: {len(value)} [[{section}]] tables: a twin holds at most {MAX_TRANSMITTERS} transmitters",
            hint="split the deployment into several twins (scene files), or merge nearby transmitters",
        )
    names = [t.get("name") for t in value if t.get("name") is not None]
    dupes = sorted({str(n) for n in names if names.count(n) > 1})
    if dupes:
        raise SceneFileError(
            f"{origin}: [[{section}]] name {', '.join(map(repr, dupes))} is given to more than one transmitter",
            hint="give each transmitter its own name (the dataset card lists them by name)",
        )


def _array(tx) -> str:
    return f"{tx.num_rows}x{tx.num_cols} {tx.pattern} {tx.polarization}"


def check_one_array(transmitters, origin: str) -> None:
    """:class:`SceneFileError` unless every transmitter (a :class:`~dtradar_data.scenes.model.TxSpec` or a file's
    ``[[tx]]`` table, anything with ``num_rows``, ``num_cols``, ``pattern`` and ``polarization``) has the array of
    the first: Sionna gives a scene one transmitter array. Checked when the scene is read, before anything is built."""
    first, *more = transmitters
    for k, tx in enumerate(more, start=1):
        if _array(tx) != _array(first):
            raise SceneFileError(
                f"{origin}: {tx_label(k, tx)} has another array than {tx_label(0, first)} ({_array(tx)} vs "
                f"{_array(first)}): Sionna gives a scene one array for all its transmitters",
                hint="give every [[tx]] the same num_rows, num_cols, pattern and polarization",
            )


def tx_tables(value) -> list:
    """The transmitter tables of a parsed document's ``tx``: one table, or the array of ``[[tx]]`` tables."""
    return list(value) if isinstance(value, (list, tuple)) else [value]


def tx_label(k: int, tx) -> str:
    """How errors and cards name transmitter ``k``: ``[[tx]] 'north'`` or ``[[tx]] #2`` (1-based like a file's)."""
    name = getattr(tx, "name", None)
    return f"[[tx]] {name!r}" if name else f"[[tx]] #{k + 1}"


def object_at(spec: SceneSpec, p) -> str | None:
    """The name of a box or prism of ``spec`` that contains the point ``p`` (x, y, z), or None. A point on a face
    counts as inside: an antenna on a wall's surface is half in it."""
    p = np.asarray(p, dtype=float)
    for b in spec.objects:
        if b.z_m <= p[2] <= b.top_m:
            t = math.radians(b.yaw_deg)
            dx, dy = p[0] - b.x_m, p[1] - b.y_m
            lx, ly = dx * math.cos(t) + dy * math.sin(t), -dx * math.sin(t) + dy * math.cos(t)
            if abs(lx) <= b.width_m / 2 and abs(ly) <= b.length_m / 2:
                return b.name
    tall = [pr for pr in spec.prisms if pr.z_m <= p[2] <= pr.top_m]
    if tall:
        from shapely.geometry import Point, Polygon  # only cities have prisms

        point = Point(p[0], p[1])
        for pr in tall:
            if Polygon(pr.exterior, pr.holes).covers(point):
                return pr.name
    return None


def check_transmitter_clear(spec: SceneSpec, origin: str, *, where: str = "[tx]") -> None:
    """:class:`SceneFileError` if a transmitter of ``spec`` stands inside one of its boxes or prisms, naming the
    object, its extent and the variant (a dynamic twin's change can cover a transmitter its blueprint leaves free)."""
    for k, tx in enumerate(spec.transmitters):
        _check_clear(spec, tx, origin, where if len(spec.transmitters) == 1 else tx_label(k, tx))


def _check_clear(spec: SceneSpec, tx, origin: str, where: str) -> None:
    pos = tuple(float(v) for v in tx.position_m)
    name = object_at(spec, pos)
    if name is None:
        return
    b = next((o for o in (*spec.objects, *spec.prisms) if o.name == name), None)
    extent = ""
    if b is not None and hasattr(b, "width_m"):
        extent = f" ({b.width_m:g} x {b.length_m:g} m centred at ({b.x_m:g}, {b.y_m:g}), z {b.z_m:g}..{b.top_m:g} m)"
    elif b is not None:
        extent = f" (z {b.z_m:g}..{b.top_m:g} m)"
    raise SceneFileError(
        f"{origin}: {where} position_m {list(pos)} is inside {name!r}{extent} in the {spec.variant} twin: the "
        "twin would be traced from within it, and its walls would hide the transmitter from most cells",
        hint="move the transmitter out of it (e.g. above it, below the ceiling) or move the object",
    )
