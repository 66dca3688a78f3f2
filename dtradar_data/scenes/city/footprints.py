"""Footprints of a city twin in one internal form: buildings, parking lots and roads as local-metre polygons.

Every source (the packaged Dallas file, a user's GeoJSON or ``.osm`` file, an OpenStreetMap download) ends up as a
:class:`CityFootprints`: a tuple of :class:`Feature` polygons in a local frame plus where they came from, their licence
and a report of what processing did. This module holds that form, the lon/lat box it covers and the errors of a
footprint source; the rest of the package builds it:

- :mod:`.frame` — the local frame (UTM metres around the box centre) and the clip rectangle;
- :mod:`.tags` — what OSM and Overture properties say: kind, height, material, road width;
- :mod:`.geojson` — processing a GeoJSON document into :class:`CityFootprints`, and the GeoJSON file reader;
- :mod:`.packaged` — the footprint files that ship with the package (Downtown Dallas);
- :mod:`.osm` — ``.osm`` XML files and OpenStreetMap downloads (osmnx), cached on disk;
- :mod:`.sources` — :func:`~.sources.load_footprints`, the one entry point that dispatches on the source.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from shapely.geometry import Polygon

from dtradar_data.core.errors import (
    DtradarError,
    InvalidCoordinatesError,
    SceneFileError,
    unknown_name,
)

__all__ = [
    "LonLatBox",
    "Feature",
    "CityFootprints",
    "FootprintsUnavailableError",
    "FootprintsEmptyError",
    "Ring",
    "CITY_BOXES",
    "KINDS",
    "MATERIALS",
]

KINDS = ("building", "parking", "road")
MATERIALS = ("brick", "marble", "concrete", "glass")  # the ITU names (as Sionna spells them) a footprint may carry


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
            raise InvalidCoordinatesError(
                f"box {values} has a non-numeric or non-finite coordinate",
                hint="give west, south, east, north as finite degrees",
            )
        if not (-180 <= self.west < self.east <= 180 and -90 <= self.south < self.north <= 90):
            raise InvalidCoordinatesError(
                f"box west={self.west} south={self.south} east={self.east} north={self.north} is not a lon/lat box",
                hint="need -180 <= west < east <= 180 and -90 <= south < north <= 90 (degrees); "
                "LonLatBox.from_corners takes (lat, lon) pairs",
            )

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
            "kind": self.kind,
            "name": self.name,
            "source_id": self.source_id,
            "exterior": [list(p) for p in self.exterior],
            "holes": [[list(p) for p in h] for h in self.holes],
            "height_m": self.height_m,
            "height_source": self.height_source,
            "material": self.material,
            "material_source": self.material_source,
            "subtype": self.subtype,
            "label": self.label,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Feature:
        ring = lambda r: tuple((float(x), float(y)) for x, y in r)  # noqa: E731
        return cls(
            kind=d["kind"],
            name=d["name"],
            source_id=d["source_id"],
            exterior=ring(d["exterior"]),
            holes=tuple(ring(h) for h in d.get("holes", ())),
            height_m=float(d.get("height_m", 0.0)),
            height_source=d.get("height_source", ""),
            material=d.get("material", "concrete"),
            material_source=d.get("material_source", ""),
            subtype=d.get("subtype", ""),
            label=d.get("label", ""),
        )

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
    report: dict  # counts; see geojson.footprints_from_geojson

    def of_kind(self, kind: str) -> tuple[Feature, ...]:
        if kind not in KINDS:
            raise unknown_name("footprint kind", kind, KINDS)
        return tuple(f for f in self.features if f.kind == kind)

    def counts(self) -> dict[str, int]:
        return {k: sum(f.kind == k for f in self.features) for k in KINDS}

    def to_dict(self) -> dict[str, Any]:
        return {
            "features": [f.to_dict() for f in self.features],
            "box": self.box.to_dict(),
            "crs": self.crs,
            "source": self.source,
            "licence": self.licence,
            "attribution": self.attribution,
            "retrieved_utc": self.retrieved_utc,
            "report": self.report,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CityFootprints:
        return cls(
            features=tuple(Feature.from_dict(f) for f in d["features"]),
            box=LonLatBox(**d["box"]),
            crs=d["crs"],
            source=d["source"],
            licence=d["licence"],
            attribution=d["attribution"],
            retrieved_utc=d.get("retrieved_utc"),
            report=dict(d.get("report", {})),
        )

    def content_hash(self) -> str:
        """sha256 of the geometry, heights and materials (not of source wording or the report): for scene hashes."""
        payload = {"box": self.box.to_dict(), "crs": self.crs, "features": [f.to_dict() for f in self.features]}
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


class FootprintsUnavailableError(DtradarError, RuntimeError):
    """OpenStreetMap footprints were asked for, but there is no cached download and no way to download them."""


class FootprintsEmptyError(SceneFileError):
    """A footprint source holds no building, parking or road footprint inside the box."""
