"""What the properties of an OpenStreetMap or Overture feature say about its footprint: kind, height, material, width.

OSM-style tags (``building``, ``height``, ``building:levels``, ``building:material``, ``amenity=parking``,
``parking``, ``highway``, ``width``, ``lanes``, ``tunnel``, ``layer``, ``location``) and Overture properties
(``overture_height``, ``num_floors``, ``building_class``). Pure functions of a property mapping; a value that is
present but not understood falls through to the next source and is counted in the caller's report.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any

__all__ = [
    "tag_text",
    "parse_length_m",
    "building_height",
    "building_material",
    "road_width",
    "classify",
    "LEVEL_HEIGHT_M",
    "DEFAULT_HEIGHT_M",
    "HEIGHT_RANGE_M",
    "TAG_MATERIALS",
    "MATERIAL_TAG_KEYS",
    "MATERIAL_HEIGHT_RULE",
    "LANE_WIDTH_M",
    "ROAD_WIDTH_M",
    "DEFAULT_ROAD_WIDTH_M",
    "ROAD_WIDTH_RANGE_M",
    "NON_SURFACE_HIGHWAYS",
    "OVERTURE_KEYS",
]

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
    "brick": "brick",
    "bricks": "brick",
    "clay": "brick",
    "masonry": "brick",
    "adobe": "brick",
    "stone": "marble",
    "sandstone": "marble",
    "limestone": "marble",
    "granite": "marble",
    "marble": "marble",
    "glass": "glass",
    "mirror": "glass",
    "glass_curtain_wall": "glass",
    "curtain_wall": "glass",
    "metal": "glass",
    "steel": "glass",
    "aluminium": "glass",
    "aluminum": "glass",
    "metal_plates": "glass",
    "concrete": "concrete",
    "reinforced_concrete": "concrete",
    "cement_block": "concrete",
    "cement": "concrete",
    "concrete_block": "concrete",
    "precast_concrete": "concrete",
    "plaster": "concrete",
    "stucco": "concrete",
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
    "motorway": 14.0,
    "trunk": 14.0,
    "primary": 10.5,
    "secondary": 7.0,
    "tertiary": 7.0,
    "motorway_link": 4.5,
    "trunk_link": 4.5,
    "primary_link": 4.5,
    "secondary_link": 4.5,
    "tertiary_link": 4.5,
    "unclassified": 6.0,
    "residential": 6.0,
    "living_street": 5.0,
    "road": 6.0,
    "busway": 7.0,
    "bus_guideway": 7.0,
    "service": 4.0,
    "track": 3.0,
    "pedestrian": 5.0,
    "footway": 2.0,
    "sidewalk": 2.0,
    "cycleway": 2.0,
    "path": 1.5,
    "bridleway": 2.0,
    "steps": 2.0,
    "construction": 6.0,
    "raceway": 8.0,
}
DEFAULT_ROAD_WIDTH_M = 5.0  # any other highway type
ROAD_WIDTH_RANGE_M = (1.0, 60.0)
# highway values that are not a built ground surface (planned, removed, or indoor)
NON_SURFACE_HIGHWAYS = frozenset({"proposed", "abandoned", "razed", "disused", "corridor", "elevator"})
OVERTURE_KEYS = ("overture_height", "num_floors", "building_class")


_FEET_INCHES = re.compile(r"(\d+(?:\.\d+)?)\s*'\s*(?:(\d+(?:\.\d+)?)\s*(?:\"|''))?")
_LENGTH = re.compile(r"([-+]?\d+(?:[.,]\d+)?)\s*(m|meters?|metres?|ft|feet|foot|')?")
_FEET_UNITS = ("ft", "feet", "foot", "'")
_LEADING_NUMBER = re.compile(r"\s*(\d+(?:\.\d+)?)")


def tag_text(value: Any) -> str | None:
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
    text = tag_text(value)
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
    text = tag_text(value)
    m = _LEADING_NUMBER.match(text) if text else None
    return float(m[1]) if m else None


def building_height(props: Mapping[str, Any], report: dict | None = None) -> tuple[float, str]:
    """(height in metres, its source) from ``height``, ``building:levels`` x 3.5, Overture ``overture_height``,
    ``num_floors`` x 3.5, else :data:`DEFAULT_HEIGHT_M`; clamped to :data:`HEIGHT_RANGE_M`.

    A value that is present but not understood (or not positive) falls through to the next source and is counted in
    ``report["height_unparsed"]``; clamping is counted in ``report["height_clamped"]``.
    """
    candidates = (
        ("height", parse_length_m, 1.0),
        ("building:levels", _parse_count, LEVEL_HEIGHT_M),
        ("overture_height", parse_length_m, 1.0),
        ("num_floors", _parse_count, LEVEL_HEIGHT_M),
    )
    height, source = DEFAULT_HEIGHT_M, "default"
    for key, parse, factor in candidates:
        if tag_text(props.get(key)) is None:
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
    return (
        tag_text(props.get("building")) == "parking"
        or tag_text(props.get("building_class")) == "parking"
        or (tag_text(props.get("amenity")) == "parking" and tag_text(props.get("parking")) == "multi-storey")
    )


def building_material(props: Mapping[str, Any], height_m: float, report: dict | None = None) -> tuple[str, str]:
    """(material, its source): a mapped ``building:material`` / ``building:facade:material`` tag, else the rule.

    See :data:`TAG_MATERIALS` and :data:`MATERIAL_HEIGHT_RULE`.
    """
    for key in MATERIAL_TAG_KEYS:
        text = tag_text(props.get(key))
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
    return ROAD_WIDTH_M.get(tag_text(props.get("highway")) or "", DEFAULT_ROAD_WIDTH_M), "default"


def classify(props: Mapping[str, Any]) -> tuple[str | None, str, str | None]:
    """(kind, subtype, None) for a footprint, or (None, "", skip reason)."""
    building = tag_text(props.get("building"))
    if building is not None and building != "no":
        if tag_text(props.get("location")) == "underground":
            return None, "", "underground_building"
        return "building", building, None
    if building is None and any(k in props for k in OVERTURE_KEYS):  # the Overture file has no `building` key
        return "building", tag_text(props.get("building_class")) or "", None
    if tag_text(props.get("amenity")) == "parking":
        parking = tag_text(props.get("parking")) or "surface"
        if parking in ("underground", "rooftop"):
            return None, "", f"{parking}_parking"  # under the ground, or on a building's roof: no ground surface
        return "parking", parking, None
    highway = tag_text(props.get("highway"))
    if highway is not None:
        if highway in NON_SURFACE_HIGHWAYS:
            return None, "", "highway_not_a_surface"
        if (tag_text(props.get("tunnel")) or "no") != "no":
            return None, "", "tunnel"
        layer = re.match(r"\s*([-+]?\d+)", tag_text(props.get("layer")) or "")
        if layer and int(layer[1]) < 0:
            return None, "", "below_ground"  # an underpass: not at street level
        return "road", highway, None
    return None, "", "not_a_footprint"
