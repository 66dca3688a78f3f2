"""Build the scenes of a city scene file: one :class:`~dtradar_data.scenes.model.SceneSpec` per quadrant and variant.

A city is one TOML file (``dallas.toml``, ``houston.toml`` beside this module are commented examples), parsed and
validated into a :class:`~dtradar_data.scenes.city.document.CityDocument` by
:func:`~dtradar_data.scenes.city.document.read_city_file` (its module lists the sections). Here a document becomes
scenes: the built-in cities' catalogue, the footprints, each quadrant's grid, transmitter and objects
(:func:`city_spec`), and the moving twin of the ``[moving]`` quadrant (:func:`city_moving_scene`).

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
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

from shapely.geometry import Polygon

from dtradar_data.core import layout
from dtradar_data.core.errors import (
    InvalidSettingError,
    SceneFileError,
    UnknownNameError,
    did_you_mean,
    unknown_name,
)
from dtradar_data.core.grid import Grid, too_many_cells
from dtradar_data.scenes.city.document import CityDocument, CityDynamic, read_city_file
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
from dtradar_data.scenes.model import Box, Prism, SceneSpec, TxSpec
from dtradar_data.scenes.moving_scene import MOVING_VARIANT, MovingScene
from dtradar_data.scenes.moving_section import moving_scene_from_section
from dtradar_data.scenes.options import check_cell_m

GROUND_THICKNESS_M = 0.2


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


# ------------------------------------------------------------------------------------------- building
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
    _check_twin(doc, quadrant, variant, scene)
    hx, hy = local_extent(doc.box, doc.city.crs)
    # the grid first: a bad --cell-m fails before the footprints are read (or downloaded); 0 is a value, not "unset"
    grid = quadrant_grid(
        quadrant, hx, hy, doc.grid.cell_m if cell_m is None else cell_m, option=cell_m is not None, city=doc.scene.name
    )
    fp = city_footprints(doc, footprints)
    area = quadrant_rect(quadrant, hx, hy)
    buildings = [f.polygon() for f in fp.of_kind("building")]
    paper = doc.quadrants[quadrant].tx_m
    near = [b for b in buildings if b.intersects(area.buffer(50))]
    tx_xy = place_transmitter(paper[:2], near, area, doc.tx.clearance_m)
    tx = _transmitter(doc, grid, (tx_xy[0], tx_xy[1], paper[2]))
    more_tx = []
    for k, asked in enumerate(doc.quadrants[quadrant].more_tx_m, start=1):  # each placed as tx_m is
        xy = place_transmitter(asked[:2], near, area, doc.tx.clearance_m)
        more_tx.append(replace(_transmitter(doc, grid, (xy[0], xy[1], asked[2])), name=f"tx{k}"))
    objects = [_ground(doc, hx, hy)]
    prisms = _prisms(doc, fp)
    provenance: dict[str, Any] = {
        "city": doc.scene.name,
        "quadrant": quadrant,
        "quadrant_rect_m": list(area.bounds),
        "footprints": _footprints_provenance(fp),
        "tx": {
            "paper_m": list(paper),
            "placed_m": list(tx.position_m),
            "moved_m": round(math.dist(paper[:2], tx_xy), 3),
            "clearance_m": doc.tx.clearance_m,
        },
    }
    if more_tx:
        provenance["more_tx"] = [
            {
                "asked_m": list(a),
                "placed_m": list(t.position_m),
                "moved_m": round(math.dist(a[:2], t.position_m[:2]), 3),
            }
            for a, t in zip(doc.quadrants[quadrant].more_tx_m, more_tx)
        ]
    description = doc.scene.description
    if variant == "dynamic":
        vehicles, provenance["dynamic"], more = _dynamic_vehicles(doc.dynamic, buildings, area)
        objects += vehicles
        description += more
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
        more_tx=tuple(more_tx),
        rx_height_m=doc.robot.rx_height_m,
        robot_height_m=doc.robot.robot_height_m,
        objects=tuple(objects),
        room=None,
        prisms=tuple(prisms),
        provenance=provenance,
        rt_defaults=doc.rt.model_dump(exclude_none=True),
    )


def _check_twin(doc: CityDocument, quadrant: str, variant: str, scene: str) -> None:
    """Refuse a moving twin (a series of scenes), a quadrant the city has not, a dynamic twin of another quadrant."""
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


def _transmitter(doc: CityDocument, grid: Grid, position_m: tuple[float, float, float]) -> TxSpec:
    """The file's transmitter array at ``position_m`` (placed clear of the buildings), looking at the grid's centre
    at the receivers' height."""
    gx0, gy0, gx1, gy1 = grid.bounds()
    return TxSpec(
        position_m=position_m,
        look_at_m=(round((gx0 + gx1) / 2, 3), round((gy0 + gy1) / 2, 3), doc.robot.rx_height_m),
        num_rows=doc.tx.num_rows,
        num_cols=doc.tx.num_cols,
        pattern=doc.tx.pattern,
        polarization=doc.tx.polarization,
        power_dbm=doc.tx.power_dbm,
    )


def _ground(doc: CityDocument, hx: float, hy: float) -> Box:
    """The ground plane under the whole city, its top at z = 0."""
    return Box(
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


def _prisms(doc: CityDocument, fp: CityFootprints) -> list[Prism]:
    """Every footprint as a prism: buildings at their height and material, lots and roads as thin surfaces."""
    prisms = []
    for f in fp.features:
        if f.kind == "building":
            prisms.append(Prism(f.name, "building", f.material, f.exterior, f.height_m, f.holes))
        else:  # parking lots and roads: flat surfaces of their own material, below the robot's clearance
            prisms.append(
                Prism(f.name, f.kind, doc.city.surface_material, f.exterior, doc.city.surface_height_m, f.holes)
            )
    return prisms


def _footprints_provenance(fp: CityFootprints) -> dict[str, Any]:
    """Where the footprints came from, under which licence, and what they hold."""
    return {
        "source": fp.source,
        "licence": fp.licence,
        "attribution": fp.attribution,
        "retrieved_utc": fp.retrieved_utc,
        "crs": fp.crs,
        "box": fp.box.to_dict(),
        "counts": fp.counts(),
        "content_hash": fp.content_hash(),
        "report": fp.report,
    }


def _dynamic_vehicles(
    dyn: CityDynamic, buildings: list[Polygon], area: Polygon
) -> tuple[list[Box], dict[str, Any], str]:
    """The dynamic twin's vehicles on its roads (the file's, or found between the buildings), their provenance and
    the sentence the scene's description gains."""
    roads = (
        [Road(r.name, r.from_m, r.to_m) for r in dyn.roads]
        if dyn.roads != "auto"
        else find_roads([b for b in buildings if b.intersects(area)], area)
    )
    vehicles = place_vehicles(roads, {"bus": dyn.buses, "car": dyn.cars}, dyn.seed, buildings, area)
    provenance = {
        "seed": dyn.seed,
        "roads": [r.to_dict() for r in roads],
        "roads_from": "auto" if dyn.roads == "auto" else "scene file",
        "vehicles": {"car": dyn.cars, "bus": dyn.buses},
    }
    description = (
        f" Dynamic twin: {dyn.cars} cars (Sionna's low-poly car mesh) and {dyn.buses} buses (metal "
        f"boxes) on {len(roads)} roads, placed with seed {dyn.seed}."
    )
    return vehicles, provenance, description


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
