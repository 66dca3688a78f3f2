"""Where a scene's transmitter may stand: one per scene file, and never inside anything the scene holds.

A transmitter inside a metal cubicle or a building traces without error and gives a table in which most cells hear
nothing, which is worse than a refusal: the dataset looks valid. So every reader refuses it when the scene is named,
before any mesh is written or ray traced:

- :func:`check_one_transmitter`: a file's ``tx`` is one ``[tx]`` table. ``[[tx]]`` (an array of tables, the form
  several transmitters would take) and ``tx = []`` are refused with what this version does instead: a twin has one
  transmitter, so a deployment with several is one dataset per transmitter.
- :func:`object_at` / :func:`check_transmitter_clear`: the transmitter is in none of the spec's boxes (objects,
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

__all__ = ["ONE_TRANSMITTER_HINT", "check_one_transmitter", "check_transmitter_clear", "object_at"]

ONE_TRANSMITTER_HINT = (
    "write one [tx] table: a twin has one transmitter; for a deployment with several, build one dataset (one scene "
    "file, its own [scene] name) per transmitter"
)


def check_one_transmitter(data: dict[str, Any], origin: str, *, section: str = "tx") -> None:
    """:class:`SceneFileError` unless the parsed TOML's ``section`` is absent (the reader names it missing) or one
    table: ``[[tx]]`` blocks and ``tx = [...]`` are refused, with how many there were and which names they gave."""
    value = data.get(section)
    if not isinstance(value, list):
        return
    if not value:
        raise SceneFileError(
            f"{origin}: {section} = [] holds no transmitter: a scene needs one", hint=ONE_TRANSMITTER_HINT
        )
    names = [t.get("name") for t in value if isinstance(t, dict) and t.get("name") is not None]
    dupes = sorted({str(n) for n in names if names.count(n) > 1})
    what = f"{len(value)} [[{section}]] tables" if len(value) > 1 else f"a [[{section}]] block (an array of tables)"
    more = f" (named {', '.join(map(repr, names))}" + (f"; {', '.join(dupes)} more than once)" if dupes else ")")
    raise SceneFileError(
        f"{origin}: {what}{more if names else ''}: this version traces one transmitter per scene",
        hint=ONE_TRANSMITTER_HINT if len(value) > 1 else f"write [{section}] (single brackets) for the transmitter",
    )


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
    """:class:`SceneFileError` if the transmitter of ``spec`` stands inside one of its boxes or prisms, naming the
    object, its extent and the variant (a dynamic twin's change can cover a transmitter its blueprint leaves free)."""
    pos = tuple(float(v) for v in spec.tx.position_m)
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
