"""Footprints of a city twin in one internal form: buildings, parking lots and roads as local-metre polygons.

Every source (the packaged Dallas file, a user's GeoJSON or ``.osm`` file, an OpenStreetMap download) ends up as a
:class:`CityFootprints`: a tuple of :class:`Feature` polygons in a local frame plus where they came from, their licence
and a report of what processing did. This module holds that form, the GeoJSON reader and :func:`load_footprints`,
the one entry point that dispatches on the source; ``osm.py`` holds the osmnx part (XML files, downloads, cache).

Local frame: longitude/latitude are projected to the UTM zone given as ``crs`` (pyproj), then the projected centre of
the lon/lat box is subtracted, so x is UTM easting and y UTM northing in metres around the box centre. UTM grid north
differs from true north by the grid convergence (about 1.2 degrees in Dallas and Houston): the lon/lat box is a
slightly rotated quadrilateral in this frame. Features are clipped to the axis-aligned rectangle
``[-hx, hx] x [-hy, hy]`` whose half sizes are half the projected distances between opposite edge midpoints of the box
(:func:`local_extent`); its corners differ from the box corners by a few metres (about 5.6 m in Dallas).

Processing of each source feature, in order of its source id: classify (building / parking / road, or skip with a
reason), project, buffer road lines to their width, repair invalid polygons (``shapely.make_valid``), drop it when it
lies outside the rectangle or clip it when it straddles the edge, snap to millimetres, split multi-part results into
one feature per part, drop parts under :data:`MIN_AREA_M2`, orient rings (exterior CCW, holes CW). Bad geometry is
counted in the report, never raised.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from pyproj import CRS, Transformer
from pyproj.exceptions import CRSError
from shapely.errors import GEOSException
from shapely.geometry import (
    GeometryCollection,
    LineString,
    MultiLineString,
    MultiPolygon,
    Polygon,
)
from shapely.geometry import box as shapely_box
from shapely.geometry import shape as shapely_shape
from shapely.geometry.polygon import orient

from dtradar_data.core.errors import (
    DtradarError,
    InvalidCoordinatesError,
    SceneFileError,
    unknown_name,
)

__all__ = [
    "LonLatBox", "Feature", "CityFootprints", "FootprintsUnavailableError", "FootprintsEmptyError",
    "local_transform", "local_extent", "utm_crs_for", "packaged_path", "packaged_files",
    "footprints_from_geojson", "read_geojson", "read_osm_xml", "download_osm", "load_footprints",
    "parse_length_m", "building_height", "building_material", "road_width",
    "CITY_BOXES", "CITY_DEFAULT_SOURCES", "DALLAS_FILE", "DALLAS_NOTICE_FILE", "DALLAS_LICENCE", "DALLAS_ATTRIBUTION",
    "KINDS", "MATERIALS", "MIN_AREA_M2", "LEVEL_HEIGHT_M", "DEFAULT_HEIGHT_M", "HEIGHT_RANGE_M",
    "TAG_MATERIALS", "MATERIAL_HEIGHT_RULE", "ROAD_WIDTH_M", "DEFAULT_ROAD_WIDTH_M", "LANE_WIDTH_M",
]

KINDS = ("building", "parking", "road")
MATERIALS = ("brick", "marble", "concrete", "glass")  # the ITU names (as Sionna spells them) a footprint may carry

# --- geometry -------------------------------------------------------------------------------------------------------
MIN_AREA_M2 = 4.0  # parts smaller than 2 m x 2 m are slivers: digitising noise or clipping leftovers, not structures
COORD_PRECISION_M = 1e-3  # snap to millimetres so output is stable across platforms and JSON round trips exactly
ROAD_QUAD_SEGS = 4  # segments per quarter circle of a buffered road's round caps/joins: few vertices, closed joints

# --- heights --------------------------------------------------------------------------------------------------------
LEVEL_HEIGHT_M = 3.5  # metres per storey for building:levels / num_floors (a common OSM 3D convention: 3-4 m)
DEFAULT_HEIGHT_M = 12.0  # no height information at all: a 3-4 storey building
HEIGHT_RANGE_M = (2.5, 600.0)  # clamp: below a shed's height, or above any existing building, is a tagging error

# --- materials ------------------------------------------------------------------------------------------------------
# building:material / building:facade:material values (OSM wiki) mapped onto the four ITU materials we use.
# Stone of any kind -> marble (the only stone among Sionna's ITU materials). Metal facades -> glass: on the
# commercial buildings where they occur they are curtain walls (aluminium mullions, glazing, spandrel panels), and
# ITU "glass" (eps_r 6.3) is closer to such walls than a solid metal plate would be. Render over masonry (plaster,
# stucco) -> concrete. Values not listed here (wood, timber, vinyl, ...) fall back to the height rule below and are
# counted in report["material_tags_unmapped"].
TAG_MATERIALS: dict[str, str] = {
    "brick": "brick", "bricks": "brick", "clay": "brick", "masonry": "brick", "adobe": "brick",
    "stone": "marble", "sandstone": "marble", "limestone": "marble", "granite": "marble", "marble": "marble",
    "glass": "glass", "mirror": "glass", "glass_curtain_wall": "glass", "curtain_wall": "glass",
    "metal": "glass", "steel": "glass", "aluminium": "glass", "aluminum": "glass", "metal_plates": "glass",
    "concrete": "concrete", "reinforced_concrete": "concrete", "cement_block": "concrete", "cement": "concrete",
    "concrete_block": "concrete", "precast_concrete": "concrete", "plaster": "concrete", "stucco": "concrete",
}
MATERIAL_TAG_KEYS = ("building:material", "building:facade:material")
# No material tag: a deterministic rule on height (first threshold the height reaches). Towers of 60 m and more
# (about 17+ storeys) in US downtowns are mostly glass curtain walls; mid-rise 25-60 m mostly concrete frames with
# concrete/precast facades; low-rise under 25 m (up to about 7 storeys) mostly brick masonry. Parking garages
# (building=parking, Overture building_class=parking, amenity=parking + parking=multi-storey) are concrete whatever
# their height. Parking lots and roads are concrete.
MATERIAL_HEIGHT_RULE: tuple[tuple[float, str], ...] = ((60.0, "glass"), (25.0, "concrete"), (0.0, "brick"))

# --- roads ----------------------------------------------------------------------------------------------------------
LANE_WIDTH_M = 3.5  # lanes x 3.5 m when a way has `lanes` but no `width`
# Carriageway widths by highway type when neither `width` nor `lanes` is tagged: typical US urban values (two lanes
# of 3.5 m for ordinary streets, more for arterials, a few metres for service roads and paths).
ROAD_WIDTH_M: dict[str, float] = {
    "motorway": 14.0, "trunk": 14.0, "primary": 10.5, "secondary": 7.0, "tertiary": 7.0,
    "motorway_link": 4.5, "trunk_link": 4.5, "primary_link": 4.5, "secondary_link": 4.5, "tertiary_link": 4.5,
    "unclassified": 6.0, "residential": 6.0, "living_street": 5.0, "road": 6.0, "busway": 7.0, "bus_guideway": 7.0,
    "service": 4.0, "track": 3.0, "pedestrian": 5.0, "footway": 2.0, "sidewalk": 2.0, "cycleway": 2.0,
    "path": 1.5, "bridleway": 2.0, "steps": 2.0, "construction": 6.0, "raceway": 8.0,
}
DEFAULT_ROAD_WIDTH_M = 5.0  # any other highway type
ROAD_WIDTH_RANGE_M = (1.0, 60.0)
# highway values that are not a built ground surface (planned, removed, or indoor)
NON_SURFACE_HIGHWAYS = frozenset({"proposed", "abandoned", "razed", "disused", "corridor", "elevator"})

# --- packaged data and the paper's boxes ----------------------------------------------------------------------------
DALLAS_FILE = "dallas_downtown_buildings_overture.geojson"
DALLAS_NOTICE_FILE = "NOTICE_dallas_downtown_buildings_overture.txt"
DALLAS_LICENCE = "ODbL-1.0"
DALLAS_ATTRIBUTION = "(c) OpenStreetMap contributors, Overture Maps Foundation, ODbL"  # wording of the NOTICE
# licence, attribution and a description of each packaged file (keyed by file name)
_PACKAGED: dict[str, tuple[str, str, str]] = {
    DALLAS_FILE: (DALLAS_LICENCE, DALLAS_ATTRIBUTION, f"packaged Overture/OSM file {DALLAS_FILE}"),
}
USER_FILE_LICENCE = "unknown (user-supplied file: check the licence of its source)"
OVERTURE_KEYS = ("overture_height", "num_floors", "building_class")


@dataclass(frozen=True)
class LonLatBox:
    """A longitude/latitude box in degrees (EPSG:4326): west < east, south < north."""

    west: float
    south: float
    east: float
    north: float

    def __post_init__(self) -> None:
        values = (self.west, self.south, self.east, self.north)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
            raise InvalidCoordinatesError(f"box {values} has a non-numeric or non-finite coordinate",
                                          hint="give west, south, east, north as finite degrees")
        if not (-180 <= self.west < self.east <= 180 and -90 <= self.south < self.north <= 90):
            raise InvalidCoordinatesError(
                f"box west={self.west} south={self.south} east={self.east} north={self.north} is not a lon/lat box",
                hint="need -180 <= west < east <= 180 and -90 <= south < north <= 90 (degrees); "
                     "LonLatBox.from_corners takes (lat, lon) pairs")

    @classmethod
    def from_corners(cls, nw: tuple[float, float], se: tuple[float, float]) -> LonLatBox:
        """From north-west and south-east corners given as (lat, lon), the way the paper gives them."""
        (north, west), (south, east) = nw, se
        return cls(west=float(west), south=float(south), east=float(east), north=float(north))

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """(west, south, east, north): osmnx 2.x's ``bbox`` order."""
        return (self.west, self.south, self.east, self.north)

    @property
    def centre(self) -> tuple[float, float]:
        """(lon, lat) of the box centre: the origin of the local frame."""
        return ((self.west + self.east) / 2.0, (self.south + self.north) / 2.0)

    def to_dict(self) -> dict[str, float]:
        return {"west": self.west, "south": self.south, "east": self.east, "north": self.north}


# The paper's city boxes (NW and SE corners as (lat, lon)) and the UTM zone each is projected to.
CITY_BOXES: dict[str, tuple[LonLatBox, str]] = {
    "dallas": (LonLatBox.from_corners(nw=(32.78243, -96.80136), se=(32.77759, -96.79671)), "EPSG:32614"),
    "houston": (LonLatBox.from_corners(nw=(29.75959, -95.37055), se=(29.75249, -95.36208)), "EPSG:32615"),
}
# Where each city's footprints come from by default: Dallas ships with the package, Houston needs OSM or a user file.
CITY_DEFAULT_SOURCES: dict[str, str] = {"dallas": f"packaged:{DALLAS_FILE}", "houston": "osm"}

Ring = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Feature:
    """One footprint polygon in local metres (x east, y north, origin = box centre); rings are not closed."""

    kind: str  # "building" | "parking" | "road"
    name: str  # unique, [a-z0-9_]+, numbered per kind in source-id order: "building_007"
    source_id: str  # OSM "way/123" or an Overture id
    exterior: Ring  # counter-clockwise
    holes: tuple[Ring, ...] = ()  # clockwise
    height_m: float = 0.0  # buildings: extrusion height; parking and roads: 0 (flat)
    height_source: str = ""  # "height" | "building:levels" | "overture_height" | "num_floors" | "default"
    material: str = "concrete"  # one of MATERIALS
    material_source: str = ""  # "tag:building:material" | "tag:building:facade:material" | "rule"
    subtype: str = ""  # building=* / Overture building_class, highway=*, parking=* ("surface" when untagged)
    label: str = ""  # the source's human name (OSM/Overture `name`), "" when none

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind, "name": self.name, "source_id": self.source_id,
            "exterior": [list(p) for p in self.exterior], "holes": [[list(p) for p in h] for h in self.holes],
            "height_m": self.height_m, "height_source": self.height_source, "material": self.material,
            "material_source": self.material_source, "subtype": self.subtype, "label": self.label,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Feature:
        ring = lambda r: tuple((float(x), float(y)) for x, y in r)  # noqa: E731
        return cls(kind=d["kind"], name=d["name"], source_id=d["source_id"], exterior=ring(d["exterior"]),
                   holes=tuple(ring(h) for h in d.get("holes", ())), height_m=float(d.get("height_m", 0.0)),
                   height_source=d.get("height_source", ""), material=d.get("material", "concrete"),
                   material_source=d.get("material_source", ""), subtype=d.get("subtype", ""),
                   label=d.get("label", ""))

    def polygon(self) -> Polygon:
        """The footprint as a shapely polygon (local metres)."""
        return Polygon(self.exterior, self.holes)


@dataclass(frozen=True)
class CityFootprints:
    """All footprints of one city box, where they came from, and what processing did to them."""

    features: tuple[Feature, ...]
    box: LonLatBox
    crs: str  # the UTM CRS of the local frame, e.g. "EPSG:32614"
    source: str  # human-readable origin
    licence: str
    attribution: str
    retrieved_utc: str | None  # download time (ISO, UTC) for OpenStreetMap downloads, None for files
    report: dict  # counts; see footprints_from_geojson

    def of_kind(self, kind: str) -> tuple[Feature, ...]:
        if kind not in KINDS:
            raise unknown_name("footprint kind", kind, KINDS)
        return tuple(f for f in self.features if f.kind == kind)

    def counts(self) -> dict[str, int]:
        return {k: sum(f.kind == k for f in self.features) for k in KINDS}

    def to_dict(self) -> dict[str, Any]:
        return {"features": [f.to_dict() for f in self.features], "box": self.box.to_dict(), "crs": self.crs,
                "source": self.source, "licence": self.licence, "attribution": self.attribution,
                "retrieved_utc": self.retrieved_utc, "report": self.report}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CityFootprints:
        return cls(features=tuple(Feature.from_dict(f) for f in d["features"]), box=LonLatBox(**d["box"]),
                   crs=d["crs"], source=d["source"], licence=d["licence"], attribution=d["attribution"],
                   retrieved_utc=d.get("retrieved_utc"), report=dict(d.get("report", {})))

    def content_hash(self) -> str:
        """sha256 of the geometry, heights and materials (not of source wording or the report): for scene hashes."""
        payload = {"box": self.box.to_dict(), "crs": self.crs, "features": [f.to_dict() for f in self.features]}
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


class FootprintsUnavailableError(DtradarError, RuntimeError):
    """OpenStreetMap footprints were asked for, but there is no cached download and no way to download them."""


class FootprintsEmptyError(SceneFileError):
    """A footprint source holds no building, parking or road footprint inside the box."""


# --- frame ----------------------------------------------------------------------------------------------------------

def utm_crs_for(box: LonLatBox) -> str:
    """The WGS 84 / UTM zone EPSG code of the box centre, e.g. "EPSG:32614" for Dallas."""
    lon, lat = box.centre
    zone = min(int((lon + 180.0) // 6.0) + 1, 60)
    return f"EPSG:{32600 + zone if lat >= 0 else 32700 + zone}"


def _check_crs(crs: str, box: LonLatBox) -> CRS:
    try:
        parsed = CRS.from_user_input(crs)
    except CRSError as e:
        raise SceneFileError(f"crs {crs!r} is not a coordinate reference system pyproj knows ({e})",
                             hint=f"use the UTM zone of the box, here {utm_crs_for(box)}") from None
    unit = parsed.axis_info[0].unit_name if parsed.axis_info else ""
    if not parsed.is_projected or unit not in ("metre", "meter"):
        raise SceneFileError(f"crs {crs!r} is not a projected CRS in metres",
                             hint=f"use the UTM zone of the box, here {utm_crs_for(box)}")
    area = parsed.area_of_use
    lon, lat = box.centre
    if area is not None and not (area.west <= lon <= area.east and area.south <= lat <= area.north):
        raise InvalidCoordinatesError(
            f"the box centre (lon {lon:.5f}, lat {lat:.5f}) lies outside the area of use of {crs} ({area.name})",
            hint=f"use the UTM zone of the box, here {utm_crs_for(box)}")
    return parsed


def local_transform(box: LonLatBox, crs: str) -> Callable[[Any, Any], tuple[Any, Any]]:
    """A function (lon, lat) -> (x, y) local metres: project to ``crs``, subtract the projected box centre.

    Takes scalars or numpy arrays (vectorised through pyproj).
    """
    _check_crs(crs, box)
    transformer = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    cx, cy = transformer.transform(*box.centre)

    def to_local(lon: Any, lat: Any) -> tuple[Any, Any]:
        x, y = transformer.transform(lon, lat)
        return x - cx, y - cy

    return to_local


def local_extent(box: LonLatBox, crs: str) -> tuple[float, float]:
    """Half sizes (hx, hy) in metres of the local clip rectangle: half the distances between opposite edge midpoints."""
    to_local = local_transform(box, crs)
    lon_c, lat_c = box.centre
    xs, ys = to_local(np.array([box.west, box.east, lon_c, lon_c]), np.array([lat_c, lat_c, box.south, box.north]))
    hx = math.hypot(xs[1] - xs[0], ys[1] - ys[0]) / 2.0
    hy = math.hypot(xs[3] - xs[2], ys[3] - ys[2]) / 2.0
    return round(hx, 3), round(hy, 3)


# --- attributes -----------------------------------------------------------------------------------------------------

_FEET_INCHES = re.compile(r"(\d+(?:\.\d+)?)\s*'\s*(?:(\d+(?:\.\d+)?)\s*(?:\"|''))?")
_LENGTH = re.compile(r"([-+]?\d+(?:[.,]\d+)?)\s*(m|meters?|metres?|ft|feet|foot|')?")
_FEET_UNITS = ("ft", "feet", "foot", "'")
_LEADING_NUMBER = re.compile(r"\s*(\d+(?:\.\d+)?)")


def _text(value: Any) -> str | None:
    """A property value as stripped text; None for missing, null or NaN."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return None
    text = str(value).strip()
    return text or None


def parse_length_m(value: Any) -> float | None:
    """An OSM length in metres: "45", "45 m", "45m", "150 ft", "12'6\\"", "45,5"; the first of "45;50".

    None when missing or not understood (the caller then falls back to the next source).
    """
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value) if math.isfinite(value) else None
    text = _text(value)
    if text is None:
        return None
    text = text.split(";")[0].strip().lower()
    if m := _FEET_INCHES.fullmatch(text):
        return (float(m[1]) * 12.0 + float(m[2] or 0.0)) * 0.0254
    if m := _LENGTH.fullmatch(text):
        number = float(m[1].replace(",", "."))
        return number * 0.3048 if m[2] in _FEET_UNITS else number
    return None


def _parse_count(value: Any) -> float | None:
    """A storey or lane count: "5", "5.5", the first of "5;6" or "2-3"; None when not understood."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value) if math.isfinite(value) else None
    text = _text(value)
    m = _LEADING_NUMBER.match(text) if text else None
    return float(m[1]) if m else None


def building_height(props: Mapping[str, Any], report: dict | None = None) -> tuple[float, str]:
    """(height in metres, its source) from ``height``, ``building:levels`` x 3.5, Overture ``overture_height``,
    ``num_floors`` x 3.5, else :data:`DEFAULT_HEIGHT_M`; clamped to :data:`HEIGHT_RANGE_M`.

    A value that is present but not understood (or not positive) falls through to the next source and is counted in
    ``report["height_unparsed"]``; clamping is counted in ``report["height_clamped"]``.
    """
    candidates = (("height", parse_length_m, 1.0), ("building:levels", _parse_count, LEVEL_HEIGHT_M),
                  ("overture_height", parse_length_m, 1.0), ("num_floors", _parse_count, LEVEL_HEIGHT_M))
    height, source = DEFAULT_HEIGHT_M, "default"
    for key, parse, factor in candidates:
        if _text(props.get(key)) is None:
            continue
        value = parse(props[key])
        if value is not None and value > 0:
            height, source = value * factor, key
            break
        if report is not None:
            report["height_unparsed"][key] = report["height_unparsed"].get(key, 0) + 1
    lo, hi = HEIGHT_RANGE_M
    clamped = min(max(height, lo), hi)
    if clamped != height and report is not None:
        report["height_clamped"] += 1
    return round(clamped, 3), source


def _is_parking_garage(props: Mapping[str, Any]) -> bool:
    return (_text(props.get("building")) == "parking" or _text(props.get("building_class")) == "parking"
            or (_text(props.get("amenity")) == "parking" and _text(props.get("parking")) == "multi-storey"))


def building_material(props: Mapping[str, Any], height_m: float, report: dict | None = None) -> tuple[str, str]:
    """(material, its source): a mapped ``building:material`` / ``building:facade:material`` tag, else the rule.

    See :data:`TAG_MATERIALS` and :data:`MATERIAL_HEIGHT_RULE`.
    """
    for key in MATERIAL_TAG_KEYS:
        text = _text(props.get(key))
        if text is None:
            continue
        for token in text.lower().split(";"):
            material = TAG_MATERIALS.get(token.strip().replace(" ", "_").replace("-", "_"))
            if material:
                return material, f"tag:{key}"
        if report is not None:
            unmapped = report["material_tags_unmapped"]
            unmapped[f"{key}={text}"] = unmapped.get(f"{key}={text}", 0) + 1
    if _is_parking_garage(props):
        return "concrete", "rule"
    for threshold, material in MATERIAL_HEIGHT_RULE:
        if height_m >= threshold:
            return material, "rule"
    return MATERIAL_HEIGHT_RULE[-1][1], "rule"


def road_width(props: Mapping[str, Any]) -> tuple[float, str]:
    """(carriageway width in metres, its source): ``width`` tag, else ``lanes`` x 3.5 m, else :data:`ROAD_WIDTH_M`."""
    lo, hi = ROAD_WIDTH_RANGE_M
    width = parse_length_m(props.get("width"))
    if width is not None and width > 0:
        return min(max(width, lo), hi), "width"
    lanes = _parse_count(props.get("lanes"))
    if lanes is not None and lanes > 0:
        return min(max(lanes * LANE_WIDTH_M, lo), hi), "lanes"
    return ROAD_WIDTH_M.get(_text(props.get("highway")) or "", DEFAULT_ROAD_WIDTH_M), "default"


def _classify(props: Mapping[str, Any]) -> tuple[str | None, str, str | None]:
    """(kind, subtype, None) for a footprint, or (None, "", skip reason)."""
    building = _text(props.get("building"))
    if building is not None and building != "no":
        if _text(props.get("location")) == "underground":
            return None, "", "underground_building"
        return "building", building, None
    if building is None and any(k in props for k in OVERTURE_KEYS):  # the Overture file has no `building` key
        return "building", _text(props.get("building_class")) or "", None
    if _text(props.get("amenity")) == "parking":
        parking = _text(props.get("parking")) or "surface"
        if parking in ("underground", "rooftop"):
            return None, "", f"{parking}_parking"  # under the ground, or on a building's roof: no ground surface
        return "parking", parking, None
    highway = _text(props.get("highway"))
    if highway is not None:
        if highway in NON_SURFACE_HIGHWAYS:
            return None, "", "highway_not_a_surface"
        if (_text(props.get("tunnel")) or "no") != "no":
            return None, "", "tunnel"
        layer = re.match(r"\s*([-+]?\d+)", _text(props.get("layer")) or "")
        if layer and int(layer[1]) < 0:
            return None, "", "below_ground"  # an underpass: not at street level
        return "road", highway, None
    return None, "", "not_a_footprint"


# --- geometry processing --------------------------------------------------------------------------------------------

def _source_key(source_id: str) -> tuple:
    """Sort key: OSM ids ("node/7", "way/9", "way/10") by type then number, any other id (Overture) as text after."""
    m = re.fullmatch(r"([a-z]+)/(\d+)", source_id)
    return (0, m[1], int(m[2]), "") if m else (1, "", 0, source_id)


def _polygons(geom: Any) -> list[Polygon]:
    if isinstance(geom, Polygon):
        return [] if geom.is_empty else [geom]
    if isinstance(geom, (MultiPolygon, GeometryCollection)):
        return [p for g in geom.geoms for p in _polygons(g)]
    return []


def _ring(coords: Any) -> tuple[tuple[float, float], ...]:
    points = [(float(x), float(y)) for x, y in list(coords)[:-1]]  # shapely rings are closed; ours are not
    return tuple(points)


def _source_id(feature: Mapping[str, Any], props: Mapping[str, Any], index: int) -> str:
    for value in (props.get("@id"), feature.get("id"), props.get("id"), props.get("osm_id")):
        text = _text(value)
        if text is not None:
            return text
    return f"feature/{index}"


def _new_report() -> dict[str, Any]:
    return {
        "input_features": 0, "kept": dict.fromkeys(KINDS, 0), "repaired": 0,
        "clipped": dict.fromkeys(KINDS, 0), "dropped_outside": dict.fromkeys(KINDS, 0),
        "split": 0, "dropped_parts": 0, "holes_filled": 0, "skipped": {}, "skipped_ids": {},
        "height_sources": {}, "height_unparsed": {}, "height_clamped": 0,
        "material_sources": {}, "materials": {}, "material_tags_unmapped": {}, "road_width_sources": {},
        "min_area_m2": MIN_AREA_M2,
    }


def _skip(report: dict, reason: str, source_id: str) -> None:
    report["skipped"][reason] = report["skipped"].get(reason, 0) + 1
    ids = report["skipped_ids"].setdefault(reason, [])
    if len(ids) < 20:  # enough to look a few up; the count is exact
        ids.append(source_id)


def _bump(counter: dict, key: str) -> None:
    counter[key] = counter.get(key, 0) + 1


def footprints_from_geojson(doc: Mapping[str, Any], box: LonLatBox, crs: str, *, source: str, licence: str,
                            attribution: str, retrieved_utc: str | None = None,
                            origin: str = "GeoJSON document") -> CityFootprints:
    """Process a parsed GeoJSON FeatureCollection (EPSG:4326) into :class:`CityFootprints`.

    ``origin`` names the document in error messages. The report counts: ``input_features``; ``kept`` per kind
    (output features, after splitting); ``repaired`` (invalid geometry made valid); ``clipped`` and
    ``dropped_outside`` per kind (source features straddling the clip rectangle / entirely outside it); ``split``
    (source features that became several features) and ``dropped_parts`` (parts under the minimum area of a feature
    that kept other parts); ``holes_filled`` (holes under the minimum area); ``skipped`` reason -> count, with up to 20
    ``skipped_ids`` per reason; ``height_sources``, ``height_unparsed``, ``height_clamped``, ``material_sources``,
    ``materials``, ``material_tags_unmapped`` (per output building); ``road_width_sources``; ``min_area_m2`` and
    ``clip_half_extent_m``.
    """
    raw_features = _feature_list(doc, origin)
    _check_geojson_crs(doc, origin)
    hx, hy = local_extent(box, crs)
    to_local = local_transform(box, crs)
    clip = shapely_box(-hx, -hy, hx, hy)
    report = _new_report()
    report["input_features"] = len(raw_features)
    report["clip_half_extent_m"] = [hx, hy]

    def project(coords: np.ndarray) -> np.ndarray:
        x, y = to_local(coords[:, 0], coords[:, 1])
        return np.column_stack([x, y])

    records = []
    for index, feature in enumerate(raw_features):
        props = feature.get("properties") if isinstance(feature, Mapping) else None
        props = props if isinstance(props, Mapping) else {}
        sid = _source_id(feature if isinstance(feature, Mapping) else {}, props, index)
        records.append((_source_key(sid), index, sid, feature, props))
    records.sort(key=lambda r: (r[0], r[1]))

    lonlat_bounds: list[tuple[float, float, float, float]] = []
    out: dict[str, list[tuple]] = {k: [] for k in KINDS}
    for _, _, sid, feature, props in records:
        kind, subtype, reason = _classify(props)
        if kind is None:
            _skip(report, reason, sid)
            continue
        geom_dict = feature.get("geometry") if isinstance(feature, Mapping) else None
        if not geom_dict:
            _skip(report, "no_geometry", sid)
            continue
        try:
            geom = shapely_shape(geom_dict)
        except (GEOSException, ValueError, TypeError, KeyError, AttributeError, IndexError):
            _skip(report, "unreadable_geometry", sid)
            continue
        coords = shapely.get_coordinates(geom)
        if geom.is_empty or len(coords) == 0:
            _skip(report, "empty_geometry", sid)
            continue
        if not np.isfinite(coords).all():
            _skip(report, "non_finite_coordinates", sid)
            continue
        if (np.abs(coords[:, 0]) > 180).any() or (np.abs(coords[:, 1]) > 90).any():
            _skip(report, "not_lonlat", sid)
            continue
        lonlat_bounds.append(geom.bounds)
        polygonal = _polygons(geom) if isinstance(geom, (Polygon, MultiPolygon, GeometryCollection)) else []
        lines = isinstance(geom, (LineString, MultiLineString))
        if kind == "road" and lines:
            width, width_source = road_width(props)
            _bump(report["road_width_sources"], width_source)
            local = shapely.transform(geom, project).buffer(width / 2.0, quad_segs=ROAD_QUAD_SEGS)
        elif polygonal:
            local = shapely.transform(geom, project)
        elif lines:
            _skip(report, "line_not_a_road", sid)  # e.g. a building drawn as an open way
            continue
        else:
            _skip(report, "point_geometry", sid)
            continue
        if not local.is_valid:
            local = shapely.make_valid(local, method="structure", keep_collapsed=False)
            report["repaired"] += 1
        if not local.intersects(clip):
            report["dropped_outside"][kind] += 1
            continue
        if not clip.contains(local):
            local = local.intersection(clip)
            report["clipped"][kind] += 1
        local = shapely.set_precision(local, COORD_PRECISION_M)
        parts = sorted(_polygons(local), key=lambda p: (-round(p.area, 6), p.centroid.x, p.centroid.y))
        kept = [p for p in parts if p.area >= MIN_AREA_M2]
        if not kept:
            _skip(report, "sliver", sid)
            continue
        report["dropped_parts"] += len(parts) - len(kept)
        report["split"] += len(kept) > 1
        for part in kept:
            holes = [h for h in part.interiors if Polygon(h).area >= MIN_AREA_M2]
            report["holes_filled"] += len(part.interiors) - len(holes)
            part = orient(Polygon(part.exterior, holes), sign=1.0)
            out[kind].append((sid, subtype, _text(props.get("name")) or "", part, props))

    if not any(out.values()):
        raise _empty_error(origin, box, report, lonlat_bounds)
    features = []
    for kind in KINDS:
        width = max(3, len(str(len(out[kind]) - 1)))
        for number, (sid, subtype, label, part, props) in enumerate(out[kind]):
            height, height_source, material, material_source = 0.0, "", "concrete", "rule"
            if kind == "building":
                height, height_source = building_height(props, report)
                material, material_source = building_material(props, height, report)
                _bump(report["height_sources"], height_source)
                _bump(report["material_sources"], material_source)
                _bump(report["materials"], material)
            features.append(Feature(
                kind=kind, name=f"{kind}_{number:0{width}d}", source_id=sid, exterior=_ring(part.exterior.coords),
                holes=tuple(_ring(h.coords) for h in part.interiors), height_m=height, height_source=height_source,
                material=material, material_source=material_source, subtype=subtype, label=label))
        report["kept"][kind] = len(out[kind])
    return CityFootprints(features=tuple(features), box=box, crs=crs, source=source, licence=licence,
                          attribution=attribution, retrieved_utc=retrieved_utc, report=report)


def _feature_list(doc: Any, origin: str) -> list:
    if not isinstance(doc, Mapping) or doc.get("type") not in ("FeatureCollection", "Feature"):
        raise SceneFileError(f"{origin}: not a GeoJSON FeatureCollection",
                             hint='give a GeoJSON file whose top level is {"type": "FeatureCollection", '
                                  '"features": [...]} (EPSG:4326 lon/lat)')
    if doc["type"] == "Feature":
        return [doc]
    features = doc.get("features")
    if not isinstance(features, list):
        raise SceneFileError(f"{origin}: the FeatureCollection has no 'features' list",
                             hint="add a 'features' array of GeoJSON Feature objects")
    return features


def _check_geojson_crs(doc: Mapping[str, Any], origin: str) -> None:
    """Reject files that declare (old-style GeoJSON ``crs`` member) a CRS other than lon/lat WGS 84."""
    crs = doc.get("crs")
    name = crs.get("properties", {}).get("name", "") if isinstance(crs, Mapping) else ""
    if name and not re.search(r"(CRS84|EPSG:{1,2}4326)$", str(name)):
        raise SceneFileError(f"{origin}: declares crs {name!r}; footprints must be lon/lat (EPSG:4326)",
                             hint=f"reproject it, e.g. ogr2ogr -t_srs EPSG:4326 out.geojson {origin}")


def _empty_error(origin: str, box: LonLatBox, report: dict, bounds: list) -> FootprintsEmptyError:
    where = f"box west {box.west} south {box.south} east {box.east} north {box.north}"
    if bounds and report["skipped"].get("not_lonlat", 0) == 0:
        arr = np.array(bounds)
        span = (f"; its footprints span lon {arr[:, 0].min():.5f}..{arr[:, 2].max():.5f}, "
                f"lat {arr[:, 1].min():.5f}..{arr[:, 3].max():.5f}")
    else:
        span = ""
    skipped = ", ".join(f"{k}: {v}" for k, v in sorted(report["skipped"].items()))
    hint = ("make sure the file covers the box and is in EPSG:4326 lon/lat, and that its features carry building=*, "
            "amenity=parking or highway=* (or Overture building fields)")
    if report["skipped"].get("not_lonlat"):
        hint = "its coordinates are not lon/lat degrees: reproject it, e.g. ogr2ogr -t_srs EPSG:4326 out.geojson in"
    return FootprintsEmptyError(
        f"{origin}: no building, parking or road footprint inside the {where} "
        f"({report['input_features']} features read{span}{'; skipped ' + skipped if skipped else ''})", hint=hint)


# --- readers --------------------------------------------------------------------------------------------------------

def packaged_path(name: str) -> Traversable:
    """A packaged data file, e.g. ``packaged_path(DALLAS_FILE)``."""
    return resources.files("dtradar_data.scenes.city") / "data" / name


def packaged_files() -> list[str]:
    """Names of the packaged footprint files (usable as ``"packaged:<name>"``)."""
    return sorted(p.name for p in (resources.files("dtradar_data.scenes.city") / "data").iterdir()
                  if p.name.endswith((".geojson", ".json")))


def _read_json_file(path: Path) -> Any:
    if not path.is_file():
        raise SceneFileError(f"{path}: no such footprint file",
                             hint="check the path (make dataset SCENE=<city> OSM=path/to/file.osm or .geojson)")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise SceneFileError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})",
                             hint="give a GeoJSON FeatureCollection in EPSG:4326 (e.g. exported from "
                                  "overpass-turbo or QGIS)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(f"{path}: cannot be read ({e})",
                             hint="check the file's permissions and that it is UTF-8 GeoJSON") from None


def read_geojson(path: str | Path, box: LonLatBox, crs: str, *, source: str | None = None,
                 licence: str | None = None, attribution: str | None = None,
                 retrieved_utc: str | None = None) -> CityFootprints:
    """Footprints from a GeoJSON FeatureCollection of (Multi)Polygons and highway LineStrings in EPSG:4326.

    Understands OSM-style properties (``building``, ``height``, ``building:levels``, ``building:material``,
    ``amenity=parking``, ``highway``, ``width``, ``lanes``) and Overture properties (``overture_height``,
    ``num_floors``, ``building_class``). Licence and attribution default to the file's own top-level or
    ``metadata`` ``licence``/``license``/``attribution`` members, else "unknown".
    """
    path = Path(path).expanduser()
    doc = _read_json_file(path)
    meta = doc.get("metadata", {}) if isinstance(doc, Mapping) else {}
    meta = meta if isinstance(meta, Mapping) else {}
    if isinstance(doc, Mapping):
        licence = licence or _text(doc.get("licence") or doc.get("license") or meta.get("licence")
                                   or meta.get("license")) or USER_FILE_LICENCE
        attribution = attribution or _text(doc.get("attribution") or meta.get("attribution")) or "unknown"
    return footprints_from_geojson(doc, box, crs, source=source or f"user file {path}", licence=licence or "",
                                   attribution=attribution or "", retrieved_utc=retrieved_utc, origin=str(path))


def read_osm_xml(path: str | Path, box: LonLatBox, crs: str) -> CityFootprints:
    """Footprints from a local OpenStreetMap XML file (``.osm``/``.xml``) through osmnx; see :mod:`.osm`."""
    from dtradar_data.scenes.city import (
        osm,  # osmnx (geopandas, networkx) is slow to import: only when needed
    )

    return osm.read_osm_xml(path, box, crs)


def download_osm(box: LonLatBox, crs: str, cache_dir: str | Path | None = None, **kwargs: Any) -> CityFootprints:
    """Footprints from OpenStreetMap (Overpass), cached in ``cache_dir``; see :func:`.osm.download_osm`."""
    from dtradar_data.scenes.city import osm

    return osm.download_osm(box, crs, cache_dir, **kwargs)


_GEOJSON_SUFFIXES = (".geojson", ".json")
_OSM_SUFFIXES = (".osm", ".xml", ".osm.gz", ".osm.bz2", ".xml.gz", ".xml.bz2")


def load_footprints(source: str | Path, box: LonLatBox, crs: str, *, cache_dir: str | Path | None = None,
                    offline: bool | None = None, scene: str | None = None) -> CityFootprints:
    """Footprints from ``source``: ``"packaged:<file name>"``, ``"osm"`` (download or cache), or a file path.

    ``cache_dir`` (OpenStreetMap downloads) defaults to ``<data root>/osm``; ``offline`` defaults to
    ``$DTRADAR_OFFLINE``; ``scene`` only names the city in error messages.
    """
    _check_crs(crs, box)
    text = str(source)
    if isinstance(source, str) and text.startswith("packaged:"):
        name = text[len("packaged:"):]
        if name not in packaged_files():
            raise unknown_name("packaged footprint file", name, packaged_files())
        licence, attribution, description = _PACKAGED.get(name, (USER_FILE_LICENCE, "unknown", f"packaged {name}"))
        with resources.as_file(packaged_path(name)) as path:
            return read_geojson(path, box, crs, source=description, licence=licence, attribution=attribution)
    if isinstance(source, str) and text == "osm":
        return download_osm(box, crs, cache_dir, offline=offline, scene=scene)
    path = Path(text).expanduser()
    lower = path.name.lower()
    if not lower.endswith(_GEOJSON_SUFFIXES + _OSM_SUFFIXES):
        raise SceneFileError(
            f"{path}: unsupported footprint file type {path.suffix or '(no extension)'!r}",
            hint="give a GeoJSON file (.geojson/.json, EPSG:4326) or an OpenStreetMap XML file (.osm/.xml), "
                 "'osm' to download from OpenStreetMap, or 'packaged:<name>' for one of: "
                 + ", ".join(packaged_files()))
    if not path.is_file():
        raise SceneFileError(f"{path}: no such footprint file",
                             hint="check the path (make dataset SCENE=<city> OSM=path/to/file.osm or .geojson), "
                                  "or use 'osm' to download from OpenStreetMap")
    if lower.endswith(_GEOJSON_SUFFIXES):
        return read_geojson(path, box, crs)
    return read_osm_xml(path, box, crs)
