"""The few facts dtradar reads from a Mitsuba/Sionna XML scene: its shapes, their files, which are the ground.

A dataset's version is a hash of its inputs, so a scene built on an XML file must be identified by the content of the
XML and of every mesh it uses, and a wrong path or a shape type dtradar cannot read must be refused when the scene is
named, not after minutes of tracing. This module reads just that much of the file (with the standard library, never
Sionna); turning the shapes into meshes, occupancy and footprints is :mod:`dtradar_data.geometry.xml_meshes`'s job,
and the scene files and loaders built on it are :mod:`dtradar_data.scenes.xml_scene`'s.
"""

from __future__ import annotations

import hashlib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.model import MeshScene
from dtradar_data.scenes.sionna_scenes import sionna_scene_names

#: Shapes whose id or file name matches this are the ground (Sionna's scenes: ``mesh-ground``, ``mesh-Plane``,
#: ``mesh-Terrain``, ``mesh-floor``); a scene file's ``[xml] ground`` names them explicitly instead.
GROUND_RE = re.compile(r"ground|floor|plane|terrain", re.IGNORECASE)
#: Mitsuba shape plugins whose geometry we can read: mesh files, and the unit primitives a hand-written XML uses.
FILE_SHAPES = ("ply", "obj")
PRIMITIVE_SHAPES = ("rectangle", "cube")


# ------------------------------------------------------------------------------------------- the XML
@dataclass(frozen=True)
class XmlShape:
    """One ``<shape>`` of a Mitsuba scene: its id, plugin type and (for mesh files) the resolved file."""

    id: str
    type: str
    file: Path | None


def read_shapes(xml: Path) -> list[XmlShape]:
    """The top-level shapes of a Mitsuba XML file; :class:`SceneFileError` for an unreadable file, a missing mesh
    file, an unsupported shape type or a scene without shapes."""
    xml = Path(xml)
    if not xml.is_file():
        raise SceneFileError(
            f"{xml}: no such XML scene file",
            hint="check the path, or name a bundled scene: " + ", ".join(sionna_scene_names()),
        )
    try:
        root = ET.parse(xml).getroot()
    except (ET.ParseError, OSError) as e:
        raise SceneFileError(
            f"{xml}: not a readable XML file ({e})",
            hint="export the scene again (Blender's Mitsuba add-on writes Sionna's format)",
        ) from e
    if root.tag != "scene":
        raise SceneFileError(
            f"{xml}: the root element is <{root.tag}>, not <scene>",
            hint="a Mitsuba/Sionna scene file starts with <scene version=...>",
        )
    shapes = []
    for i, el in enumerate(root.findall("shape")):
        kind = el.get("type", "")
        sid = el.get("id") or el.get("name") or f"shape-{i}"
        if kind in FILE_SHAPES:
            fn = next((s.get("value") for s in el.findall("string") if s.get("name") == "filename"), None)
            if not fn:
                raise SceneFileError(
                    f"{xml}: shape {sid!r} ({kind}) has no filename",
                    hint='add <string name="filename" value="meshes/...ply"/>',
                )
            file = (xml.parent / fn).resolve()
            if not file.is_file():
                raise SceneFileError(
                    f"{xml}: shape {sid!r} refers to {fn}, which does not exist ({file})",
                    hint="mesh paths are relative to the XML file's folder; copy the meshes along",
                )
            shapes.append(XmlShape(sid, kind, file))
        elif kind in PRIMITIVE_SHAPES:
            shapes.append(XmlShape(sid, kind, None))
        else:
            raise SceneFileError(
                f"{xml}: shape {sid!r} has type {kind!r}, which dtradar cannot read",
                hint=f"use {', '.join(FILE_SHAPES + PRIMITIVE_SHAPES)} shapes (export meshes as PLY)",
            )
    if not shapes:
        raise SceneFileError(f"{xml}: the scene has no shapes", hint="a scene needs at least a ground and buildings")
    return shapes


def content_sha256(xml: Path, shapes: list[XmlShape]) -> str:
    """sha256 over the XML and each referenced mesh file (once, in order of first use), each length-prefixed."""
    h = hashlib.sha256()
    seen: set[Path] = set()
    for f in [Path(xml)] + [s.file for s in shapes if s.file is not None]:
        if f in seen:
            continue
        seen.add(f)
        data = f.read_bytes()
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


def mesh_scene(xml: Path, label: str, ground: list[str] | None = None) -> MeshScene:
    """The :class:`MeshScene` of an XML file: content hash and ground shapes (by name unless given)."""
    shapes = read_shapes(xml)
    ids = [s.id for s in shapes]
    if ground is None:
        ground = [s.id for s in shapes if GROUND_RE.search(s.id) or (s.file and GROUND_RE.search(s.file.name))]
    else:
        for g in ground:
            if g not in ids:
                close = did_you_mean(g, ids)
                raise SceneFileError(
                    f"{xml}: [xml] ground names shape {g!r}, which the XML does not have"
                    + (f"; {close}" if close else ""),
                    hint="use the shape's id attribute",
                )
    return MeshScene(xml=label, sha256=content_sha256(xml, shapes), ground=tuple(ground), path=str(Path(xml).resolve()))
