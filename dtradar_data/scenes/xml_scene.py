"""Scenes built on a Mitsuba/Sionna XML file: Sionna's bundled cities (``sionna:munich`` ...) or the user's own XML.

Three ways to name one:

- ``sionna:munich`` (also ``sionna:etoile``, ``sionna:florence``, ``sionna:san_francisco``,
  ``sionna:simple_street_canyon``): the scene that ships inside the installed sionna-rt wheel, with the grid,
  transmitter and robot of :data:`SIONNA_DEFAULTS`. Its dataset is named ``sionna-munich/...`` (dataset scene names
  allow only ``[a-z0-9_-]``), and that name works too.
- ``path/to/scene.xml``: a user's Mitsuba/Sionna XML, with the grid and transmitter on the command line
  (``--grid X0 Y0 CELL_M NX NY --tx X Y Z``).
- a small scene file (TOML)::

      format = 1
      [scene]  name, title, [description, source, licence, attribution]
      [xml]    path = "sionna:munich" | "relative/or/absolute.xml",  [ground = ["mesh-ground", ...]]
      [grid]   x0_m, y0_m, cell_m, nx, ny
      [tx]     position_m = [x, y, z], [look_at_m, num_rows, num_cols, pattern, polarization, power_dbm]
      [robot]  [rx_height_m = 1.5, robot_height_m = 1.5]

The XML is parsed here only for what identifies it (its shapes' files, hashed into the spec's digest) and for which
shapes are the ground; meshes, occupancy and footprints are :mod:`dtradar_data.geometry.xml_meshes`'s business. Bundled
files are found through package metadata, never by importing Sionna (only ``dtradar_data.rt`` may).
"""

from __future__ import annotations

import hashlib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Annotated, Any, Literal

import tomllib
from pydantic import BeforeValidator, Field, ValidationError

from dtradar_data.core.errors import (
    SceneFileError,
    did_you_mean,
    unknown_name,
)
from dtradar_data.core.files import installed_file
from dtradar_data.core.grid import Grid
from dtradar_data.core.ids import SCENE_RE
from dtradar_data.scenes.fields import Num, Pos, PosInt, SceneFileModel, SceneName, Text
from dtradar_data.scenes.model import (
    OUTDOOR_RT_DEFAULTS,
    PATTERNS,
    POLARIZATIONS,
    MeshScene,
    SceneSpec,
    TxSpec,
)

FORMAT = 1
SIONNA_PREFIX = "sionna:"
SIONNA_DIST = "sionna-rt"
#: Shapes whose id or file name matches this are the ground (Sionna's scenes: ``mesh-ground``, ``mesh-Plane``,
#: ``mesh-Terrain``, ``mesh-floor``); a scene file's ``[xml] ground`` names them explicitly instead.
GROUND_RE = re.compile(r"ground|floor|plane|terrain", re.IGNORECASE)
#: Mitsuba shape plugins whose geometry we can read: mesh files, and the unit primitives a hand-written XML uses.
FILE_SHAPES = ("ply", "obj")
PRIMITIVE_SHAPES = ("rectangle", "cube")

SIONNA_LICENCE = "Apache-2.0 (sionna-rt; scene geometry from OpenStreetMap, ODbL)"
SIONNA_ATTRIBUTION = "NVIDIA Sionna RT example scenes; building data (c) OpenStreetMap contributors"

#: The five bundled city scenes: a grid over the central streets and a transmitter in the open above one.
#: Chosen from the scenes' building footprints at 1.5 m (see README, "Sionna scenes"): each grid is 400 m x 400 m
#: around the scene's centre at 5 m cells (the street canyon: all of it at 2 m), so it traces in minutes on 2 CPU
#: cores; each TX stands over a street or square, at least 15 m from every building, 20 m above the ground (the
#: paper's city transmitters are at 18-20 m).
SIONNA_DEFAULTS: dict[str, dict[str, Any]] = {
    "simple_street_canyon": {
        "title": "Sionna simple street canyon",
        "description": "Sionna RT's bundled street canyon: six blocks along one street, on a concrete floor.",
        "grid": {"x0_m": -49.0, "y0_m": -29.0, "cell_m": 2.0, "nx": 50, "ny": 30},
        "tx": {"position_m": [-30.0, 0.0, 20.0]},
    },
    "munich": {
        "title": "Sionna Munich (Frauenkirche)",
        "description": "Sionna RT's bundled twin of central Munich around the Frauenkirche and Marienplatz.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [40.0, 90.0, 20.0]},  # in the square north of the Neues Rathaus
    },
    "etoile": {
        "title": "Sionna Paris Etoile",
        "description": "Sionna RT's bundled twin of the Place Charles de Gaulle (Arc de Triomphe), Paris.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [-60.0, 0.0, 20.0]},  # on the roundabout, east of the Arc
    },
    "florence": {
        "title": "Sionna Florence",
        "description": "Sionna RT's bundled twin of central Florence.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [-50.0, -30.0, 20.0]},  # in the square south of the cathedral quarter
    },
    "san_francisco": {
        "title": "Sionna San Francisco",
        "description": "Sionna RT's bundled twin of part of San Francisco, buildings on terrain.",
        "grid": {"x0_m": -197.5, "y0_m": -197.5, "cell_m": 5.0, "nx": 80, "ny": 80},
        "tx": {"position_m": [40.0, 40.0, 33.0]},  # a crossing; the terrain there is at 13 m
    },
}


# ------------------------------------------------------------------------------------------- names
def sionna_scene_names() -> list[str]:
    """``["sionna:etoile", ...]``: the bundled scenes a build can name."""
    return [SIONNA_PREFIX + n for n in sorted(SIONNA_DEFAULTS)]


def dataset_scene_name(name: str) -> str:
    """``"sionna:san_francisco"`` -> ``"sionna-san_francisco"``: the dataset grammar has no colon."""
    return name.replace(":", "-")


def sionna_dataset_scenes() -> list[str]:
    return [dataset_scene_name(n) for n in sionna_scene_names()]


def is_sionna_name(scene: str) -> bool:
    """Whether ``scene`` is meant as a bundled Sionna scene (known or not): ``sionna:...`` or ``sionna-...``."""
    return scene.startswith((SIONNA_PREFIX, "sionna-"))


def sionna_key(scene: str) -> str:
    """``"sionna:munich"`` or ``"sionna-munich"`` -> ``"munich"``; :class:`UnknownNameError` with did-you-mean."""
    key = scene.split(":", 1)[1] if scene.startswith(SIONNA_PREFIX) else scene.removeprefix("sionna-")
    if key not in SIONNA_DEFAULTS:
        raise unknown_name("Sionna scene", scene, sionna_scene_names())
    return key


def sionna_xml(key: str) -> Path:
    """The bundled XML of one Sionna scene, found through package metadata (importing sionna is ``rt``'s job)."""
    return installed_file(SIONNA_DIST, f"sionna/rt/scenes/{key}/{key}.xml", f"the scene sionna:{key}")


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


# ------------------------------------------------------------------------------------------- the scene file
def _vec3(value: Any) -> tuple[float, float, float]:
    if not (
        isinstance(value, (list, tuple))
        and len(value) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        raise ValueError(f"must be [x, y, z] in metres, got {value!r}")
    return tuple(float(v) for v in value)  # type: ignore[return-value]


Vec3 = Annotated[tuple[float, float, float], BeforeValidator(_vec3)]


class MeshSceneMeta(SceneFileModel):
    name: SceneName
    title: Text
    description: Text = "A scene built on a Mitsuba/Sionna XML file."
    source: Text = "a Mitsuba/Sionna XML scene"
    licence: Text = "unknown (the XML's own)"
    attribution: Text = "the XML scene's authors"


class XmlSection(SceneFileModel):
    path: Text
    ground: list[Text] | None = None


class GridSection(SceneFileModel):
    x0_m: Num
    y0_m: Num
    cell_m: Pos
    nx: PosInt
    ny: PosInt


class TxSection(SceneFileModel):
    position_m: Vec3
    look_at_m: Vec3 | None = None
    num_rows: PosInt = 8
    num_cols: PosInt = 2
    pattern: Literal[PATTERNS] = "tr38901"  # type: ignore[valid-type]
    polarization: Literal[POLARIZATIONS] = "VH"  # type: ignore[valid-type]
    power_dbm: Num = 0.0


class RobotSection(SceneFileModel):
    rx_height_m: Pos = 1.5
    robot_height_m: Pos = 1.5


class MeshSceneDocument(SceneFileModel):
    format: int = Field(FORMAT, ge=FORMAT, le=FORMAT)
    scene: MeshSceneMeta
    xml: XmlSection
    grid: GridSection
    tx: TxSection
    robot: RobotSection = RobotSection()


def is_mesh_scene_file(path: Path) -> bool:
    """Whether a TOML scene file is of this form (it has an ``[xml]`` section) rather than a room."""
    try:
        return "xml" in tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # the room reader reports the problem


def _parse(data: dict[str, Any], origin: str) -> MeshSceneDocument:
    try:
        return MeshSceneDocument.model_validate(data)
    except ValidationError as exc:
        e = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")[0]
        loc = [str(p) for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function")))]
        where = f"[{'.'.join(loc[:-1])}]" if len(loc) > 1 else "top level"
        field = loc[-1] if loc else "(document)"
        what = {"extra_forbidden": f"unknown key {field!r}", "missing": f"missing {field!r}"}.get(
            e["type"], f"{field}: {e['msg'].removeprefix('Value error, ')}"
        )
        raise SceneFileError(
            f"{origin}: {where}: {what}",
            hint="sections: [scene] name, title; [xml] path; [grid] x0_m, y0_m, cell_m, nx, ny; "
            "[tx] position_m; [robot] rx_height_m, robot_height_m (README, 'Sionna scenes')",
        ) from exc


def _spec(
    doc: MeshSceneDocument,
    base: MeshScene,
    variant: str,
    *,
    grid: tuple | None,
    tx: tuple | None,
    cell_m: float | None,
    origin: str,
) -> SceneSpec:
    g = doc.grid
    the_grid = Grid(float(g.x0_m), float(g.y0_m), float(g.cell_m), int(g.nx), int(g.ny))
    if grid is not None:
        the_grid = grid_from_option(grid)
    if cell_m is not None:  # same area, other cells
        x0, y0, x1, y1 = the_grid.bounds()
        nx, ny = max(1, round((x1 - x0) / cell_m)), max(1, round((y1 - y0) / cell_m))
        the_grid = Grid(x0 + cell_m / 2, y0 + cell_m / 2, float(cell_m), nx, ny)
    t = doc.tx
    position = t.position_m if tx is None else tx_from_option(tx)
    if variant != "blueprint":
        raise SceneFileError(
            f"{origin} has no {variant} twin: only its blueprint",
            hint="build it with --variant blueprint (the default `all` does this for XML scenes)",
        )
    return SceneSpec(
        scene=doc.scene.name,
        variant=variant,
        title=doc.scene.title,
        description=doc.scene.description,
        source=doc.scene.source,
        licence=doc.scene.licence,
        attribution=doc.scene.attribution,
        grid=the_grid,
        tx=TxSpec(
            position_m=tuple(position),
            look_at_m=t.look_at_m or _grid_centre(the_grid, doc.robot.rx_height_m),
            num_rows=t.num_rows,
            num_cols=t.num_cols,
            pattern=t.pattern,
            polarization=t.polarization,
            power_dbm=t.power_dbm,
        ),
        rx_height_m=doc.robot.rx_height_m,
        robot_height_m=doc.robot.robot_height_m,
        objects=(),
        base=base,
        provenance={"xml": base.xml, "xml_path": base.path},
        rt_defaults=dict(OUTDOOR_RT_DEFAULTS) if base.xml.startswith("sionna:") else {},
    )


def _grid_centre(grid: Grid, height_m: float) -> tuple[float, float, float]:
    """Where a transmitter without ``look_at_m`` points: the grid's centre at receiver height (a tr38901 array
    otherwise faces +x and leaves the cells behind it in its back lobe), as for the city quadrants."""
    x0, y0, x1, y1 = grid.bounds()
    return (round((x0 + x1) / 2, 3), round((y0 + y1) / 2, 3), float(height_m))


def grid_from_option(grid: tuple) -> Grid:
    """``--grid X0 Y0 CELL NX NY`` as a :class:`Grid` (checked)."""
    try:
        x0, y0, cell, nx, ny = grid
        out = Grid(float(x0), float(y0), float(cell), int(nx), int(ny))
    except (TypeError, ValueError) as e:
        raise SceneFileError(
            f"--grid {grid!r}: expected X0 Y0 CELL_M NX NY", hint="e.g. --grid -100 -100 5 40 40"
        ) from e
    if not (out.cell_m > 0 and out.nx > 0 and out.ny > 0 and out.nx == nx and out.ny == ny):
        raise SceneFileError(
            f"--grid {grid!r}: CELL_M must be positive, NX and NY positive integers",
            hint="e.g. --grid -100 -100 5 40 40",
        )
    return out


def tx_from_option(tx: tuple) -> tuple[float, float, float]:
    try:
        return _vec3(list(tx))
    except ValueError as e:
        raise SceneFileError(f"--tx {tx!r}: expected X Y Z in metres", hint="e.g. --tx 0 0 20") from e


def load_mesh_scene_file(path: str | Path, variant: str, *, grid=None, tx=None, cell_m=None) -> SceneSpec:
    """A scene file with an ``[xml]`` section; ``path`` in it is ``sionna:<name>`` or relative to the file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(f"{path}: cannot read scene file ({e})", hint="check the path") from e
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{path}: not valid TOML: {e}", hint="fix the syntax at the reported line") from e
    doc = _parse(data, str(path))
    ref = doc.xml.path
    if is_sionna_name(ref):
        key = sionna_key(ref)
        base = mesh_scene(sionna_xml(key), SIONNA_PREFIX + key, doc.xml.ground)
    else:
        xml = Path(ref).expanduser()
        xml = xml if xml.is_absolute() else path.parent / xml
        if not xml.is_file():
            raise SceneFileError(
                f"{path}: [xml] path: {ref!r} does not exist ({xml})",
                hint="a relative path is relative to the scene file; or use sionna:<name>",
            )
        base = mesh_scene(xml, xml.name, doc.xml.ground)
    return _spec(doc, base, variant, grid=grid, tx=tx, cell_m=cell_m, origin=str(path))


def load_sionna_spec(scene: str, variant: str, *, grid=None, tx=None, cell_m=None) -> SceneSpec:
    """A bundled Sionna scene (``sionna:munich`` or ``sionna-munich``) with its defaults or the given overrides."""
    key = sionna_key(scene)
    d = SIONNA_DEFAULTS[key]
    doc = _parse(
        {
            "scene": {
                "name": dataset_scene_name(SIONNA_PREFIX + key),
                "title": d["title"],
                "description": d["description"],
                "source": f"sionna-rt {_sionna_version()}: sionna/rt/scenes/{key}/{key}.xml",
                "licence": SIONNA_LICENCE,
                "attribution": SIONNA_ATTRIBUTION,
            },
            "xml": {"path": SIONNA_PREFIX + key},
            "grid": d["grid"],
            "tx": d["tx"],
        },
        f"sionna:{key}",
    )
    base = mesh_scene(sionna_xml(key), SIONNA_PREFIX + key)
    return _spec(doc, base, variant, grid=grid, tx=tx, cell_m=cell_m, origin=f"sionna:{key}")


def load_xml_spec(path: str | Path, variant: str, *, grid=None, tx=None, cell_m=None) -> SceneSpec:
    """A user's XML file named directly, with ``grid`` (``--grid``) and ``tx`` (``--tx``) required: a sensible grid
    and transmitter cannot be guessed from arbitrary geometry. The dataset is named after the file's stem."""
    path = Path(path).expanduser()
    if grid is None or tx is None:
        raise SceneFileError(
            f"{path}: an XML scene needs a grid and a transmitter",
            hint="pass --grid X0 Y0 CELL_M NX NY and --tx X Y Z, or write a small scene file "
            "with [xml] path = ... (README, 'Sionna scenes')",
        )
    base = mesh_scene(path, path.name)
    stem = re.sub(r"[^a-z0-9_-]+", "-", path.stem.lower()).strip("-_") or "xml-scene"
    name = stem if SCENE_RE.fullmatch(stem) else f"xml-{stem}"
    doc = _parse(
        {
            "scene": {"name": name, "title": f"XML scene {path.name}"},
            "xml": {"path": str(path)},
            "grid": {"x0_m": 0, "y0_m": 0, "cell_m": 1, "nx": 1, "ny": 1},
            "tx": {"position_m": [0, 0, 0]},
        },
        str(path),
    )
    return _spec(doc, base, variant, grid=grid, tx=tx, cell_m=cell_m, origin=str(path))


def _sionna_version() -> str:
    try:
        return metadata.version(SIONNA_DIST)
    except metadata.PackageNotFoundError:
        return "(not installed)"
