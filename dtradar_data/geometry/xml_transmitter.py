"""Where a transmitter may stand in a scene built on a Mitsuba/Sionna XML file: over the scene, above its ground,
and outside every shape.

The readers check a transmitter against the spec's own boxes and prisms when a scene is named
(:mod:`dtradar_data.scenes.transmitters`); the shapes of an XML's meshes need the meshes read, so this check runs
when such a scene is built, before anything is traced (the meshes are read then anyway, for the occupancy grid).
A point is inside a shape if the shape's horizontal section at the transmitter's height holds it (a closed
building), or if it is under the shape's shadow from above within the shape's height (the open shells that exported
city meshes often are: walls without a floor, a roof as the only closed ring). Off the scene means outside the
bounding box of all the XML's shapes: the tracer sees only what the XML holds, so a transmitter beyond it would
reach the grid across ground and buildings the twin does not have.
"""

from __future__ import annotations

import shapely

from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_data.geometry.xml_meshes import FLAT_M, ground_height, mesh_section, mesh_shadow, shape_meshes
from dtradar_data.scenes.model import SceneSpec

__all__ = ["check_transmitter_in_mesh", "mesh_shape_at"]

_HINT = "move the transmitter: the scene file's [tx] position_m, or --tx X Y Z"


def mesh_shape_at(spec: SceneSpec, p) -> str | None:
    """The id of a (non-ground) shape of the spec's XML that holds the point ``p`` (x, y, z), or None."""
    x, y, z = (float(v) for v in p)
    point = shapely.Point(x, y)
    for sid, mesh in shape_meshes(spec.base):
        if sid in spec.base.ground or len(mesh.faces) == 0:
            continue
        (x0, y0, z0), (x1, y1, z1) = mesh.bounds
        if not (x0 <= x <= x1 and y0 <= y <= y1 and z0 <= z <= z1) or z1 - z0 < FLAT_M:
            continue
        section = mesh_section(mesh, z)
        if section is not None and section.covers(point):
            return sid
        shadow = mesh_shadow(mesh)
        if shadow is not None and shadow.covers(point):
            return sid
    return None


def check_transmitter_in_mesh(spec: SceneSpec) -> None:
    """:class:`InvalidCoordinatesError` if a transmitter of an XML-based spec is off the XML's shapes, below its
    ground, or inside one of its shapes (named). Specs without an XML base pass (their readers checked them)."""
    if spec.base is None:
        return
    meshes = [m for _, m in shape_meshes(spec.base) if len(m.faces)]
    for k, tx in enumerate(spec.transmitters):
        label = "the transmitter" if not spec.more_tx else f"transmitter {k}" + (f" ({tx.name})" if tx.name else "")
        _check_one(spec, meshes, tx.position_m, label)


def _check_one(spec: SceneSpec, meshes, position_m, label: str) -> None:
    x, y, z = (float(v) for v in position_m)
    where = f"{spec.name}: {label} at ({x:g}, {y:g}, {z:g}) m"
    if meshes:
        x0 = min(m.bounds[0][0] for m in meshes)
        y0 = min(m.bounds[0][1] for m in meshes)
        x1 = max(m.bounds[1][0] for m in meshes)
        y1 = max(m.bounds[1][1] for m in meshes)
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            raise InvalidCoordinatesError(
                f"{where} is off the scene: {spec.base.xml}'s shapes span x {x0:.1f}..{x1:.1f}, y {y0:.1f}..{y1:.1f} m",
                hint=_HINT + " (coordinates are the XML's own frame, in metres)",
            )
    g = float(ground_height(spec, x, y))
    if z <= g:
        raise InvalidCoordinatesError(f"{where} is under the ground (at {g:.2f} m there)", hint=_HINT)
    sid = mesh_shape_at(spec, (x, y, z))
    if sid is not None:
        raise InvalidCoordinatesError(
            f"{where} is inside the shape {sid!r} of {spec.base.xml}: the twin would be traced from within it",
            hint=_HINT + " (e.g. onto a square or a street, or above the roof)",
        )
