"""Scenes built on a Mitsuba/Sionna XML file: Sionna's bundled cities (``sionna:munich`` ...) or the user's own XML.

The ray tracer takes any Mitsuba scene, but a dataset needs more than geometry (a grid, a transmitter, the robot's
heights, a name and a licence) and must be rebuilt the same from a name; this module supplies them, in three ways.
``sionna:munich`` (also ``sionna:etoile``, ``sionna:florence``, ``sionna:san_francisco``,
``sionna:simple_street_canyon``; its dataset scene ``sionna-munich`` works too) takes the grid, transmitter and robot
of :data:`~dtradar_data.scenes.sionna_scenes.SIONNA_DEFAULTS`; ``path/to/scene.xml`` takes the grid and transmitter
from the command line (``--grid X0 Y0 CELL_M NX NY --tx X Y Z``), since they cannot be guessed from arbitrary
geometry; and a small scene file (TOML) with an ``[xml]`` section names the XML and writes them down::

      format = 1
      [scene]  name, title, [description, source, licence, attribution]
      [xml]    path = "sionna:munich" | "relative/or/absolute.xml",  [ground = ["mesh-ground", ...]]
      [grid]   x0_m, y0_m, cell_m, nx, ny
      [tx]     position_m = [x, y, z], [look_at_m, num_rows, num_cols, pattern, polarization, power_dbm]
      [robot]  [rx_height_m = 1.5, robot_height_m = 1.5]
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import tomllib
from pydantic import BeforeValidator, Field, ValidationError

from dtradar_data.core.errors import InvalidSettingError, SceneFileError
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
from dtradar_data.scenes.names import check_user_scene_name
from dtradar_data.scenes.options import check_cell_m, grid_from_option, grid_with_cell, tx_from_option
from dtradar_data.scenes.sionna_scenes import (
    SIONNA_ATTRIBUTION,
    SIONNA_DEFAULTS,
    SIONNA_LICENCE,
    SIONNA_PREFIX,
    dataset_scene_name,
    is_sionna_name,
    sionna_base,
    sionna_key,
    sionna_version,
    sionna_xml,
)
from dtradar_data.scenes.transmitters import check_one_array, check_transmitter_tables, tx_tables
from dtradar_data.scenes.xml_shapes import mesh_scene

FORMAT = 1


# ------------------------------------------------------------------------------------------- the scene file
def _vec3(value: Any) -> tuple[float, float, float]:
    if not (
        isinstance(value, (list, tuple))
        and len(value) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    ):
        raise ValueError(f"must be [x, y, z], three finite numbers of metres, got {value!r}")
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
    name: Text | None = None
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
    tx: TxSection | list[TxSection]
    """One ``[tx]`` table, or one ``[[tx]]`` table per transmitter (the first is transmitter 0)."""
    robot: RobotSection = RobotSection()


def is_mesh_scene_file(path: Path) -> bool:
    """Whether a TOML scene file is of this form (it has an ``[xml]`` section) rather than a room."""
    try:
        return "xml" in tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # the room reader reports the problem


def _parse(data: dict[str, Any], origin: str) -> MeshSceneDocument:
    check_transmitter_tables(data, origin)
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
    read_base: Callable[[], MeshScene],
    variant: str,
    *,
    grid: tuple | None,
    tx: tuple | None,
    cell_m: float | None,
    origin: str,
    rt: dict | None = None,
) -> SceneSpec:
    g = doc.grid
    if grid is not None:
        the_grid = grid_from_option(grid)
    else:
        the_grid = _file_grid(g, origin)
    if cell_m is not None:  # same area, other cells
        the_grid = grid_with_cell(the_grid, check_cell_m(cell_m))
    tables = tx_tables(doc.tx)
    if tx is not None and len(tables) > 1:
        raise SceneFileError(
            f"{origin}: --tx places one transmitter, and this scene has {len(tables)} ([[tx]] tables)",
            hint="edit the [[tx]] tables' position_m in the scene file instead of passing --tx",
        )
    check_one_array(tables, origin)
    if variant != "blueprint":
        raise SceneFileError(
            f"{origin} has no {variant} twin: only its blueprint",
            hint="build it with --variant blueprint (the default `all` does this for XML scenes)",
        )
    base = read_base()  # reads and hashes the meshes: only once the cheap checks above have passed
    return SceneSpec(
        scene=doc.scene.name,
        variant=variant,
        title=doc.scene.title,
        description=doc.scene.description,
        source=doc.scene.source,
        licence=doc.scene.licence,
        attribution=doc.scene.attribution,
        grid=the_grid,
        tx=_tx_spec(tables[0], the_grid, doc.robot.rx_height_m, None if tx is None else tx_from_option(tx)),
        more_tx=tuple(_tx_spec(t, the_grid, doc.robot.rx_height_m) for t in tables[1:]),
        rx_height_m=doc.robot.rx_height_m,
        robot_height_m=doc.robot.robot_height_m,
        objects=(),
        base=base,
        provenance={"xml": base.xml, "xml_path": base.path},
        rt_defaults={**OUTDOOR_RT_DEFAULTS, **(rt or {})} if base.xml.startswith("sionna:") else {},
    )


def _tx_spec(t: TxSection, grid: Grid, rx_height_m: float, position=None) -> TxSpec:
    """One transmitter of the file (at ``position`` when ``--tx`` moves it), looking at the grid's centre unless
    the file says where."""
    return TxSpec(
        position_m=tuple(t.position_m if position is None else position),
        look_at_m=_grid_centre(grid, rx_height_m) if t.look_at_m is None else t.look_at_m,
        num_rows=t.num_rows,
        num_cols=t.num_cols,
        pattern=t.pattern,
        polarization=t.polarization,
        power_dbm=t.power_dbm,
        name=t.name,
    )


def _file_grid(g: GridSection, origin: str) -> Grid:
    """The scene file's [grid]; too many cells is the file's mistake, named with its section."""
    try:
        return Grid(float(g.x0_m), float(g.y0_m), float(g.cell_m), int(g.nx), int(g.ny))
    except InvalidSettingError as e:
        raise SceneFileError(
            f"{origin}: [grid]: {e.message.removeprefix('invalid receiver grid: ')}",
            hint="use larger cells (cell_m) or fewer of them (nx, ny)",
        ) from e


def _grid_centre(grid: Grid, height_m: float) -> tuple[float, float, float]:
    """Where a transmitter without ``look_at_m`` points: the grid's centre at receiver height (a tr38901 array
    otherwise faces +x and leaves the cells behind it in its back lobe), as for the city quadrants."""
    x0, y0, x1, y1 = grid.bounds()
    return (round((x0 + x1) / 2, 3), round((y0 + y1) / 2, 3), float(height_m))


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
    check_user_scene_name(doc.scene.name, path)  # before the meshes are read and hashed
    ref = doc.xml.path
    if is_sionna_name(ref):
        key = sionna_key(ref)

        def base() -> MeshScene:
            return mesh_scene(sionna_xml(key), SIONNA_PREFIX + key, doc.xml.ground)

    else:
        xml = Path(ref).expanduser()
        xml = xml if xml.is_absolute() else path.parent / xml
        if not xml.is_file():
            raise SceneFileError(
                f"{path}: [xml] path: {ref!r} does not exist ({xml})",
                hint="a relative path is relative to the scene file; or use sionna:<name>",
            )

        def base() -> MeshScene:
            return mesh_scene(xml, xml.name, doc.xml.ground)

    return _spec(doc, base, variant, grid=grid, tx=tx, cell_m=cell_m, origin=str(path))


def load_sionna_spec(scene: str, variant: str, *, grid=None, tx=None, cell_m=None) -> SceneSpec:
    """A bundled Sionna scene (``sionna:munich`` or ``sionna-munich``) with its defaults or the given overrides."""
    key = sionna_key(scene)
    d = SIONNA_DEFAULTS[key]
    base = sionna_base(key)  # munich-10tx traces munich's XML
    doc = _parse(
        {
            "scene": {
                "name": dataset_scene_name(SIONNA_PREFIX + key),
                "title": d["title"],
                "description": d["description"],
                "source": f"sionna-rt {sionna_version()}: sionna/rt/scenes/{base}/{base}.xml",
                "licence": SIONNA_LICENCE,
                "attribution": SIONNA_ATTRIBUTION,
            },
            "xml": {"path": SIONNA_PREFIX + base},
            "grid": d["grid"],
            "tx": d["tx"],
        },
        f"sionna:{key}",
    )
    return _spec(
        doc,
        lambda: mesh_scene(sionna_xml(key), SIONNA_PREFIX + base),
        variant,
        grid=grid,
        tx=tx,
        cell_m=cell_m,
        origin=f"sionna:{key}",
        rt=d.get("rt"),
    )


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
    stem = re.sub(r"[^a-z0-9_-]+", "-", path.stem.lower()).strip("-_") or "xml-scene"
    name = stem if SCENE_RE.fullmatch(stem) else f"xml-{stem}"
    check_user_scene_name(
        name,
        path,
        where="the scene name taken from the file name",
        rename="rename the .xml file (the dataset is named after it), or write a scene file with [xml] path = ... "
        "and a [scene] name of your own (README, 'Sionna scenes')",
    )
    doc = _parse(
        {
            "scene": {"name": name, "title": f"XML scene {path.name}"},
            "xml": {"path": str(path)},
            "grid": {"x0_m": 0, "y0_m": 0, "cell_m": 1, "nx": 1, "ny": 1},
            "tx": {"position_m": [0, 0, 0]},
        },
        str(path),
    )
    return _spec(doc, lambda: mesh_scene(path, path.name), variant, grid=grid, tx=tx, cell_m=cell_m, origin=str(path))
