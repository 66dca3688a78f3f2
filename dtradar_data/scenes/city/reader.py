"""Read a city scene file (TOML) into one :class:`~dtradar_data.scenes.model.SceneSpec` per quadrant and variant.

A city is one file (``dallas.toml``, ``houston.toml`` beside this module are commented examples)::

    format = 1
    [scene]        name, title, description
    [city]         nw_lat_lon, se_lat_lon, crs, footprints, [ground_material, surface_material, surface_height_m]
    [grid]         cell_m
    [robot]        rx_height_m, robot_height_m
    [tx]           [num_rows, num_cols, pattern, polarization, power_dbm, clearance_m]
    [rt]           [samples_per_src, max_num_paths_per_src]      (instead of the indoor RTSettings defaults)
    [quadrants.qN] tx_m = [x, y, z]                      (N = 1..4; the paper's Tables III and IV)
    [dynamic]      quadrant, seed, cars, buses, roads = [{name, from_m, to_m}, ...] or "auto"
    [moving]       quadrant, description, [base, dt_s, horizon_s], [[moving.mover]] (vehicles driving along lanes:
                   :mod:`dtradar_data.scenes.moving_section`; read only for the moving twin, :func:`city_moving_scene`)

Each quadrant is its own dataset, ``<city>-qN/blueprint`` (and ``<city>-qN/dynamic`` for the dynamic quadrant): its
grid covers the quadrant, the geometry is the whole city (buildings outside the quadrant still reflect), the
transmitter is the quadrant's. The local frame is the footprints' (UTM metres around the box centre, see
:mod:`~dtradar_data.scenes.city.frame`); quadrants tile the box around the centre, their grids meeting at it.
``footprints`` is ``packaged:<file>``, ``osm`` (download or cache) or a file path; ``make dataset ... OSM=path``
replaces it for one build.
"""

from __future__ import annotations

import functools
import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import tomllib
from pydantic import BaseModel, BeforeValidator, Field, ValidationError

from dtradar_data.core import layout
from dtradar_data.core.errors import (
    InvalidSettingError,
    SceneFileError,
    UnknownNameError,
    did_you_mean,
    unknown_name,
)
from dtradar_data.core.grid import Grid, too_many_cells
from dtradar_data.scenes.city.footprints import CityFootprints, LonLatBox
from dtradar_data.scenes.city.frame import local_extent
from dtradar_data.scenes.city.sources import load_footprints
from dtradar_data.scenes.city.streets import (
    QUADRANT_SIGNS,
    Road,
    find_roads,
    place_transmitter,
    place_vehicles,
    quadrant_rect,
)
from dtradar_data.scenes.fields import (
    Material,
    Num,
    Pos,
    PosInt,
    SceneFileModel,
    SceneName,
    Text,
)
from dtradar_data.scenes.model import (
    PATTERNS,
    POLARIZATIONS,
    Box,
    Prism,
    SceneSpec,
    TxSpec,
)
from dtradar_data.scenes.moving_scene import MOVING_VARIANT, MovingScene
from dtradar_data.scenes.moving_section import moving_scene_from_section
from dtradar_data.scenes.names import check_user_scene_name
from dtradar_data.scenes.options import check_cell_m

FORMAT = 1
GROUND_THICKNESS_M = 0.2


def _lat_lon(value: Any) -> tuple[float, float]:
    if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)):
        raise ValueError(f"must be [lat, lon] in degrees, got {value!r}")
    return float(value[0]), float(value[1])


def _vec(n: int):
    def check(value: Any) -> tuple[float, ...]:
        if not (
            isinstance(value, list)
            and len(value) == n
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        ):
            raise ValueError(f"must be a list of {n} numbers, got {value!r}")
        return tuple(float(v) for v in value)

    return check


LatLon = Annotated[tuple[float, float], BeforeValidator(_lat_lon)]
Vec2 = Annotated[tuple[float, float], BeforeValidator(_vec(2))]
Vec3 = Annotated[tuple[float, float, float], BeforeValidator(_vec(3))]


class CitySceneMeta(SceneFileModel):
    name: SceneName
    title: Text
    description: Text


class CitySection(SceneFileModel):
    nw_lat_lon: LatLon
    se_lat_lon: LatLon
    crs: Text
    footprints: Text
    ground_material: Material = "concrete"
    surface_material: Material = "concrete"
    surface_height_m: Pos = 0.02


class CityGrid(SceneFileModel):
    cell_m: Pos


class CityRobot(SceneFileModel):
    rx_height_m: Pos = 1.5
    robot_height_m: Pos = 1.5


class CityTx(SceneFileModel):
    num_rows: PosInt = 8
    num_cols: PosInt = 2
    pattern: Literal[PATTERNS] = "tr38901"  # type: ignore[valid-type]
    polarization: Literal[POLARIZATIONS] = "VH"  # type: ignore[valid-type]
    power_dbm: Num = 0.0
    clearance_m: Num = Field(default=3.0, ge=0)


class CityRt(SceneFileModel):
    """Ray-tracing settings the city needs instead of the (indoor) RTSettings defaults."""

    samples_per_src: PosInt | None = None
    max_num_paths_per_src: PosInt | None = None


class Quadrant(SceneFileModel):
    tx_m: Vec3


class RoadModel(SceneFileModel):
    name: Text
    from_m: Vec2
    to_m: Vec2


class CityDynamic(SceneFileModel):
    quadrant: Literal["q1", "q2", "q3", "q4"]
    seed: int = 0
    cars: int = Field(default=0, ge=0)
    buses: int = Field(default=0, ge=0)
    roads: list[RoadModel] | Literal["auto"] = "auto"


class CityDocument(SceneFileModel):
    format: Literal[1]
    scene: CitySceneMeta
    city: CitySection
    grid: CityGrid
    robot: CityRobot = CityRobot()
    tx: CityTx = CityTx()
    rt: CityRt = CityRt()
    quadrants: dict[Literal["q1", "q2", "q3", "q4"], Quadrant]
    dynamic: CityDynamic | None = None
    moving: dict[str, Any] | None = None
    """Checked only when the moving twin is read (:func:`city_moving_scene`), so it never touches the others."""

    @property
    def box(self) -> LonLatBox:
        return LonLatBox.from_corners(self.city.nw_lat_lon, self.city.se_lat_lon)


# ------------------------------------------------------------------------------------------- the catalogue
def _city_dir():
    return resources.files("dtradar_data.scenes.city")


def city_names() -> list[str]:
    """The built-in cities (a ``<city>.toml`` each beside this module)."""
    return sorted(p.name[:-5] for p in _city_dir().iterdir() if p.name.endswith(".toml"))


def city_file(city: str) -> Path:
    names = city_names()
    if city not in names:
        raise unknown_name("city", city, names)
    return Path(str(_city_dir() / f"{city}.toml"))


def quadrant_scenes(city: str) -> list[str]:
    """``["dallas-q1", ..., "dallas-q4"]``: the dataset scene names of a built-in city."""
    return [f"{city}-{q}" for q in sorted(read_city_file(city_file(city)).quadrants)]


def split_quadrant_scene(scene: str) -> tuple[str, str] | None:
    """``"dallas-q3"`` -> ``("dallas", "q3")`` for a built-in city's quadrant, else None."""
    city, sep, quadrant = scene.rpartition("-")
    if sep and city in city_names() and quadrant in QUADRANT_SIGNS:
        return city, quadrant
    return None


# ------------------------------------------------------------------------------------------- reading
def read_city_file(path: str | Path) -> CityDocument:
    """Parse and validate a city scene file; :class:`SceneFileError` names the file, the section and the field."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(
            f"{path}: cannot read city scene file ({getattr(e, 'strerror', None) or e})", hint="check the path"
        ) from e
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{path}: not valid TOML: {e}", hint="fix the syntax at the reported line") from e
    doc = parse_city(data, origin=str(path))
    check_user_scene_name(doc.scene.name, path, derived=tuple(f"{doc.scene.name}-{q}" for q in sorted(doc.quadrants)))
    return doc


def parse_city(data: dict[str, Any], *, origin: str = "<city>") -> CityDocument:
    try:
        return CityDocument.model_validate(data)
    except ValidationError as exc:
        errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
        e = errors[0]
        loc = [str(p) for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function")))]
        where = f"[{'.'.join(loc[:-1])}]" if len(loc) > 1 else "top level"
        field = loc[-1] if loc else "(document)"
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        if e["type"] == "extra_forbidden":
            allowed = _allowed_keys(loc[:-1])
            close = did_you_mean(field, allowed)
            raise SceneFileError(
                f"{origin}: {where}: unknown key {field!r}" + (f"; {close}" if close else "") + more,
                hint="allowed keys: " + ", ".join(allowed),
            ) from exc
        if e["type"] == "missing":
            raise SceneFileError(
                f"{origin}: {where}: missing {'section' if len(loc) == 1 else 'field'} {field!r}" + more,
                hint="see dtradar_data/scenes/city/dallas.toml for the expected form",
            ) from exc
        msg = e["msg"].removeprefix("Value error, ")
        hint = e.get("ctx", {}).get("hint") or "see dtradar_data/scenes/city/dallas.toml for the expected form"
        raise SceneFileError(f"{origin}: {where}: {field}: {msg}" + more, hint=hint) from exc


def _allowed_keys(loc: list[str]) -> list[str]:
    model: Any = CityDocument
    for part in loc:
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            break
        ann = field.annotation
        model = next(
            (a for a in getattr(ann, "__args__", (ann,)) if isinstance(a, type) and issubclass(a, BaseModel)), ann
        )
    return sorted(getattr(model, "model_fields", {}))


@functools.lru_cache(maxsize=8)
def _footprints(source: str, box: LonLatBox, crs: str, data_root: str, scene: str) -> CityFootprints:
    # keyed on the data root too: an OpenStreetMap download is cached there
    return load_footprints(source, box, crs, cache_dir=Path(data_root) / "osm", scene=scene)


def city_footprints(doc: CityDocument, source: str | None = None) -> CityFootprints:
    """The city's footprints from ``source`` (default: the file's ``[city] footprints``)."""
    return _footprints(
        str(doc.city.footprints if source is None else source),
        doc.box,
        doc.city.crs,
        str(layout.data_root()),
        doc.scene.name,
    )


def quadrant_grid(quadrant: str, hx: float, hy: float, cell_m: float, *, option: bool = False, city: str = "") -> Grid:
    """The quadrant's grid: whole cells from the box centre outwards (quadrant grids meet at the centre).
    ``option``: ``cell_m`` is ``--cell-m`` (named in errors), not the ``[grid] cell_m`` of the file of ``city``."""
    what = "--cell-m" if option else f"{city + '.toml: ' if city else ''}[grid] cell_m"
    if option:
        cell_m = check_cell_m(cell_m)
    nx, ny = math.floor(hx / cell_m + 1e-9), math.floor(hy / cell_m + 1e-9)
    if nx < 1 or ny < 1:
        raise SceneFileError(
            f"{what} {cell_m:g} is larger than the quadrant ({2 * hx:.0f} x {2 * hy:.0f} m city)",
            hint="use a smaller --cell-m" if option else "use a smaller cell_m in [grid]",
        )
    problem = too_many_cells(nx, ny)
    if problem:
        raise (InvalidSettingError if option else SceneFileError)(
            f"{what} {cell_m:g} over a {hx:.0f} x {hy:.0f} m quadrant: {problem}",
            hint="use larger cells (--cell-m)" if option else "use a larger cell_m in [grid]",
        )
    sx, sy = QUADRANT_SIGNS[quadrant]
    x0 = cell_m / 2 if sx > 0 else -nx * cell_m + cell_m / 2
    y0 = cell_m / 2 if sy > 0 else -ny * cell_m + cell_m / 2
    return Grid(round(x0, 6), round(y0, 6), float(cell_m), nx, ny)


def city_spec(
    doc: CityDocument, quadrant: str, variant: str, *, footprints: str | None = None, cell_m: float | None = None
) -> SceneSpec:
    """One quadrant of a city as a scene: ground plane, buildings, lots and roads, the quadrant's grid and TX."""
    scene = f"{doc.scene.name}-{quadrant}"
    if variant == MOVING_VARIANT:
        raise SceneFileError(
            f"{scene}/{MOVING_VARIANT} is a moving twin, a series of scenes, not one",
            hint="read it with city_moving_scene / load_city_moving (a MovingScene: spec_at(k) is snapshot k)",
        )
    if quadrant not in doc.quadrants:
        raise unknown_name(f"quadrant of {doc.scene.name}", quadrant, sorted(doc.quadrants))
    dyn = doc.dynamic
    if variant == "dynamic" and (dyn is None or dyn.quadrant != quadrant):
        has = f"{doc.scene.name}-{dyn.quadrant}/dynamic" if dyn else "none"
        raise UnknownNameError(
            f"{scene} has no dynamic twin (the dynamic twin of {doc.scene.name} is {has})",
            hint=f"use {scene}/blueprint" + (f" or {has}" if dyn else ""),
        )
    hx, hy = local_extent(doc.box, doc.city.crs)
    # the grid first: a bad --cell-m fails before the footprints are read (or downloaded); 0 is a value, not "unset"
    grid = quadrant_grid(
        quadrant, hx, hy, doc.grid.cell_m if cell_m is None else cell_m, option=cell_m is not None, city=doc.scene.name
    )
    fp = city_footprints(doc, footprints)
    area = quadrant_rect(quadrant, hx, hy)
    buildings = [f.polygon() for f in fp.of_kind("building")]

    paper = doc.quadrants[quadrant].tx_m
    tx_xy = place_transmitter(
        paper[:2], [b for b in buildings if b.intersects(area.buffer(50))], area, doc.tx.clearance_m
    )
    gx0, gy0, gx1, gy1 = grid.bounds()
    tx = TxSpec(
        position_m=(tx_xy[0], tx_xy[1], paper[2]),
        look_at_m=(round((gx0 + gx1) / 2, 3), round((gy0 + gy1) / 2, 3), doc.robot.rx_height_m),
        num_rows=doc.tx.num_rows,
        num_cols=doc.tx.num_cols,
        pattern=doc.tx.pattern,
        polarization=doc.tx.polarization,
        power_dbm=doc.tx.power_dbm,
    )

    ground = Box(
        name="ground",
        kind="floor",
        material=doc.city.ground_material,
        x_m=0.0,
        y_m=0.0,
        width_m=round(2 * hx, 3),
        length_m=round(2 * hy, 3),
        height_m=GROUND_THICKNESS_M,
        z_m=-GROUND_THICKNESS_M,
    )
    prisms = []
    for f in fp.features:
        if f.kind == "building":
            prisms.append(Prism(f.name, "building", f.material, f.exterior, f.height_m, f.holes))
        else:  # parking lots and roads: flat surfaces of their own material, below the robot's clearance
            prisms.append(
                Prism(f.name, f.kind, doc.city.surface_material, f.exterior, doc.city.surface_height_m, f.holes)
            )
    objects = [ground]
    provenance: dict[str, Any] = {
        "city": doc.scene.name,
        "quadrant": quadrant,
        "quadrant_rect_m": list(area.bounds),
        "footprints": {
            "source": fp.source,
            "licence": fp.licence,
            "attribution": fp.attribution,
            "retrieved_utc": fp.retrieved_utc,
            "crs": fp.crs,
            "box": fp.box.to_dict(),
            "counts": fp.counts(),
            "content_hash": fp.content_hash(),
            "report": fp.report,
        },
        "tx": {
            "paper_m": list(paper),
            "placed_m": list(tx.position_m),
            "moved_m": round(math.dist(paper[:2], tx_xy), 3),
            "clearance_m": doc.tx.clearance_m,
        },
    }
    description = doc.scene.description
    if variant == "dynamic":
        roads = (
            [Road(r.name, r.from_m, r.to_m) for r in dyn.roads]
            if dyn.roads != "auto"
            else find_roads([b for b in buildings if b.intersects(area)], area)
        )
        vehicles = place_vehicles(roads, {"bus": dyn.buses, "car": dyn.cars}, dyn.seed, buildings, area)
        objects += vehicles
        provenance["dynamic"] = {
            "seed": dyn.seed,
            "roads": [r.to_dict() for r in roads],
            "roads_from": "auto" if dyn.roads == "auto" else "scene file",
            "vehicles": {"car": dyn.cars, "bus": dyn.buses},
        }
        description += (
            f" Dynamic twin: {dyn.cars} cars (Sionna's low-poly car mesh) and {dyn.buses} buses (metal "
            f"boxes) on {len(roads)} roads, placed with seed {dyn.seed}."
        )
    q = quadrant.upper()
    return SceneSpec(
        scene=scene,
        variant=variant,
        title=f"{doc.scene.title} {q} ({variant})",
        description=description,
        source=f"{fp.source}; scene file {doc.scene.name}.toml",
        licence=fp.licence,
        attribution=fp.attribution,
        grid=grid,
        tx=tx,
        rx_height_m=doc.robot.rx_height_m,
        robot_height_m=doc.robot.robot_height_m,
        objects=tuple(objects),
        room=None,
        prisms=tuple(prisms),
        provenance=provenance,
        rt_defaults=doc.rt.model_dump(exclude_none=True),
    )


def load_city_spec(
    scene: str, variant: str, *, footprints: str | None = None, cell_m: float | None = None
) -> SceneSpec:
    """A built-in city quadrant by dataset scene name (``"dallas-q3"``)."""
    parts = split_quadrant_scene(scene)
    if parts is None:
        raise unknown_name("city quadrant", scene, [s for c in city_names() for s in quadrant_scenes(c)])
    city, quadrant = parts
    return city_spec(read_city_file(city_file(city)), quadrant, variant, footprints=footprints, cell_m=cell_m)


def city_moving_scene(
    doc: CityDocument, quadrant: str, *, footprints: str | None = None, cell_m: float | None = None
) -> MovingScene:
    """The moving twin of the city's ``[moving]`` quadrant: its movers (vehicles driving along lanes) over that
    quadrant's blueprint (or dynamic twin, ``base = "dynamic"``); ``footprints`` and ``cell_m`` as for
    :func:`city_spec` (the default step follows ``cell_m``)."""
    city, scene, section = doc.scene.name, f"{doc.scene.name}-{quadrant}", doc.moving
    if quadrant not in doc.quadrants:
        raise unknown_name(f"quadrant of {city}", quadrant, sorted(doc.quadrants))
    if section is None:
        raise UnknownNameError(
            f"{scene} has no moving twin ({city} declares none)",
            hint=f"add a [moving] section with quadrant = {quadrant!r} and [[moving.mover]] tables to {city}.toml",
        )
    has = section.get("quadrant")
    if has not in doc.quadrants:
        close = did_you_mean(str(has), doc.quadrants)
        raise SceneFileError(
            f"{city}.toml: [moving]: "
            + ("missing field 'quadrant'" if has is None else f"quadrant {has!r} is not a quadrant of the city")
            + (f"; {close}" if close and has is not None else ""),
            hint="give the quadrant the movers move in: quadrant = one of " + ", ".join(sorted(doc.quadrants)),
        )
    if has != quadrant:
        raise UnknownNameError(
            f"{scene} has no moving twin (the moving twin of {city} is {city}-{has}/{MOVING_VARIANT})",
            hint=f"use {city}-{has}",
        )
    rest = {k: v for k, v in section.items() if k != "quadrant"}
    return moving_scene_from_section(
        rest,
        lambda variant: city_spec(doc, quadrant, variant, footprints=footprints, cell_m=cell_m),
        origin=f"{city}.toml",
        title=f"{doc.scene.title} {quadrant.upper()} ({MOVING_VARIANT})",
        description=doc.scene.description,
    )


def load_city_moving(scene: str, *, footprints: str | None = None, cell_m: float | None = None) -> MovingScene:
    """The moving twin of a built-in city quadrant by dataset scene name (``"dallas-q3"``)."""
    parts = split_quadrant_scene(scene)
    if parts is None:
        raise unknown_name("city quadrant", scene, [s for c in city_names() for s in quadrant_scenes(c)])
    city, quadrant = parts
    return city_moving_scene(read_city_file(city_file(city)), quadrant, footprints=footprints, cell_m=cell_m)
