"""Process a GeoJSON document (EPSG:4326) into :class:`~.footprints.CityFootprints`, and read GeoJSON files.

Processing of each source feature, in order of its source id: classify (building / parking / road, or skip with a
reason; :func:`.tags.classify`), project (:func:`.frame.local_transform`), buffer road lines to their width, repair
invalid polygons (``shapely.make_valid``), drop it when it lies outside the clip rectangle (:func:`.frame.local_extent`)
or clip it when it straddles the edge, snap to millimetres, split multi-part results into one feature per part, drop
parts under :data:`MIN_AREA_M2`, orient rings (exterior CCW, holes CW). Bad geometry is counted in the report, never
raised. Every other source (packaged files, ``.osm`` files, OpenStreetMap downloads) ends up here.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import shapely
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

from dtradar_data.core.errors import SceneFileError
from dtradar_data.scenes.city.footprints import KINDS, CityFootprints, Feature, FootprintsEmptyError, LonLatBox
from dtradar_data.scenes.city.frame import local_extent, local_transform
from dtradar_data.scenes.city.tags import building_height, building_material, classify, road_width, tag_text

__all__ = [
    "footprints_from_geojson",
    "read_geojson",
    "MIN_AREA_M2",
    "COORD_PRECISION_M",
    "ROAD_QUAD_SEGS",
    "USER_FILE_LICENCE",
]

# --- geometry -------------------------------------------------------------------------------------------------------
MIN_AREA_M2 = 4.0  # parts smaller than 2 m x 2 m are slivers: digitising noise or clipping leftovers, not structures
COORD_PRECISION_M = 1e-3  # snap to millimetres so output is stable across platforms and JSON round trips exactly
ROAD_QUAD_SEGS = 4  # segments per quarter circle of a buffered road's round caps/joins: few vertices, closed joints
USER_FILE_LICENCE = "unknown (user-supplied file: check the licence of its source)"


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
        text = tag_text(value)
        if text is not None:
            return text
    return f"feature/{index}"


def _new_report() -> dict[str, Any]:
    return {
        "input_features": 0,
        "kept": dict.fromkeys(KINDS, 0),
        "repaired": 0,
        "clipped": dict.fromkeys(KINDS, 0),
        "dropped_outside": dict.fromkeys(KINDS, 0),
        "split": 0,
        "dropped_parts": 0,
        "holes_filled": 0,
        "skipped": {},
        "skipped_ids": {},
        "height_sources": {},
        "height_unparsed": {},
        "height_clamped": 0,
        "material_sources": {},
        "materials": {},
        "material_tags_unmapped": {},
        "road_width_sources": {},
        "min_area_m2": MIN_AREA_M2,
    }


def _skip(report: dict, reason: str, source_id: str) -> None:
    report["skipped"][reason] = report["skipped"].get(reason, 0) + 1
    ids = report["skipped_ids"].setdefault(reason, [])
    if len(ids) < 20:  # enough to look a few up; the count is exact
        ids.append(source_id)


def _bump(counter: dict, key: str) -> None:
    counter[key] = counter.get(key, 0) + 1


def footprints_from_geojson(
    doc: Mapping[str, Any],
    box: LonLatBox,
    crs: str,
    *,
    source: str,
    licence: str,
    attribution: str,
    retrieved_utc: str | None = None,
    origin: str = "GeoJSON document",
) -> CityFootprints:
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
    project = _projector(box, crs)
    clip = shapely_box(-hx, -hy, hx, hy)
    report = _new_report()
    report["input_features"] = len(raw_features)
    report["clip_half_extent_m"] = [hx, hy]

    out, lonlat_bounds = _processed(raw_features, project, clip, report)
    if not any(out.values()):
        raise _empty_error(origin, box, report, lonlat_bounds)
    return CityFootprints(
        features=tuple(_named_features(out, report)),
        box=box,
        crs=crs,
        source=source,
        licence=licence,
        attribution=attribution,
        retrieved_utc=retrieved_utc,
        report=report,
    )


def _processed(
    raw_features: list, project: Callable, clip: Polygon, report: dict
) -> tuple[dict[str, list[tuple]], list[tuple[float, float, float, float]]]:
    """Each kind's kept parts as ``(source id, subtype, label, polygon, properties)``, and the lon/lat bounds read."""
    lonlat_bounds: list[tuple[float, float, float, float]] = []
    out: dict[str, list[tuple]] = {k: [] for k in KINDS}
    for sid, feature, props in _ordered_records(raw_features):
        kind, subtype, reason = classify(props)
        if kind is None:
            _skip(report, reason, sid)
            continue
        geom = _lonlat_geometry(feature, sid, report)
        if geom is None:
            continue
        lonlat_bounds.append(geom.bounds)  # kept for the error message when nothing lands inside the box
        local = _local_geometry(geom, kind, props, project, sid, report)
        if local is None:
            continue
        local = _clipped(local, clip, kind, report)
        if local is None:
            continue
        label = tag_text(props.get("name")) or ""
        out[kind] += [(sid, subtype, label, part, props) for part in _kept_parts(local, sid, report)]
    return out, lonlat_bounds


def _projector(box: LonLatBox, crs: str) -> Callable[[np.ndarray], np.ndarray]:
    """A ``shapely.transform`` function taking lon/lat coordinates to the box's local metres."""
    to_local = local_transform(box, crs)

    def project(coords: np.ndarray) -> np.ndarray:
        x, y = to_local(coords[:, 0], coords[:, 1])
        return np.column_stack([x, y])

    return project


def _ordered_records(raw_features: list) -> list[tuple[str, Any, Mapping[str, Any]]]:
    """``(source id, feature, properties)`` of every feature, in order of source id, then position in the file."""
    records = []
    for index, feature in enumerate(raw_features):
        props = feature.get("properties") if isinstance(feature, Mapping) else None
        props = props if isinstance(props, Mapping) else {}
        sid = _source_id(feature if isinstance(feature, Mapping) else {}, props, index)
        records.append((_source_key(sid), index, sid, feature, props))
    # Sorted so that the output (names, report order) does not depend on the order the source wrote its features in.
    records.sort(key=lambda r: (r[0], r[1]))
    return [(sid, feature, props) for _, _, sid, feature, props in records]


def _lonlat_geometry(feature: Any, sid: str, report: dict) -> Any:
    """A feature's geometry when it is readable, non-empty and in lon/lat degrees, else None (skip counted)."""
    geom_dict = feature.get("geometry") if isinstance(feature, Mapping) else None
    if not geom_dict:
        _skip(report, "no_geometry", sid)
        return None
    try:
        geom = shapely_shape(geom_dict)
    except (GEOSException, ValueError, TypeError, KeyError, AttributeError, IndexError):
        _skip(report, "unreadable_geometry", sid)
        return None
    coords = shapely.get_coordinates(geom)
    if geom.is_empty or len(coords) == 0:
        _skip(report, "empty_geometry", sid)
        return None
    if not np.isfinite(coords).all():
        _skip(report, "non_finite_coordinates", sid)
        return None
    if (np.abs(coords[:, 0]) > 180).any() or (np.abs(coords[:, 1]) > 90).any():
        _skip(report, "not_lonlat", sid)
        return None
    return geom


def _local_geometry(geom: Any, kind: str, props: Mapping[str, Any], project: Callable, sid: str, report: dict) -> Any:
    """The geometry as a valid area in local metres (a road line buffered to its width), or None (skip counted)."""
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
        return None
    else:
        _skip(report, "point_geometry", sid)
        return None
    if not local.is_valid:
        local = shapely.make_valid(local, method="structure", keep_collapsed=False)
        report["repaired"] += 1
    return local


def _clipped(local: Any, clip: Polygon, kind: str, report: dict) -> Any:
    """``local`` cut to the clip rectangle, or None when it lies wholly outside (both counted per kind)."""
    if not local.intersects(clip):
        report["dropped_outside"][kind] += 1
        return None
    if not clip.contains(local):
        local = local.intersection(clip)
        report["clipped"][kind] += 1
    return local


def _kept_parts(local: Any, sid: str, report: dict) -> list[Polygon]:
    """The snapped, oriented polygons of ``local`` of at least the minimum area, largest first; none for a sliver."""
    local = shapely.set_precision(local, COORD_PRECISION_M)
    # Rounded area first, then the centroid: a stable order of parts whatever order the geometry library gives them.
    parts = sorted(_polygons(local), key=lambda p: (-round(p.area, 6), p.centroid.x, p.centroid.y))
    kept = [p for p in parts if p.area >= MIN_AREA_M2]
    if not kept:
        _skip(report, "sliver", sid)
        return []
    report["dropped_parts"] += len(parts) - len(kept)
    report["split"] += len(kept) > 1
    oriented = []
    for part in kept:
        holes = [h for h in part.interiors if Polygon(h).area >= MIN_AREA_M2]
        report["holes_filled"] += len(part.interiors) - len(holes)
        oriented.append(orient(Polygon(part.exterior, holes), sign=1.0))
    return oriented


def _named_features(out: dict[str, list[tuple]], report: dict) -> list[Feature]:
    """The output features, kind by kind, numbered ``<kind>_<NNN>``; buildings get their height and material."""
    features = []
    for kind in KINDS:
        # Zero-padded to the widest number of the kind, so that names sort in numeric order.
        width = max(3, len(str(len(out[kind]) - 1)))
        for number, (sid, subtype, label, part, props) in enumerate(out[kind]):
            height, height_source, material, material_source = _surface(kind, props, report)
            features.append(
                Feature(
                    kind=kind,
                    name=f"{kind}_{number:0{width}d}",
                    source_id=sid,
                    exterior=_ring(part.exterior.coords),
                    holes=tuple(_ring(h.coords) for h in part.interiors),
                    height_m=height,
                    height_source=height_source,
                    material=material,
                    material_source=material_source,
                    subtype=subtype,
                    label=label,
                )
            )
        report["kept"][kind] = len(out[kind])
    return features


def _surface(kind: str, props: Mapping[str, Any], report: dict) -> tuple[float, str, str, str]:
    """``(height, its source, material, its source)`` of one output feature, counted in the report for a building."""
    if kind != "building":
        return 0.0, "", "concrete", "rule"  # lots and roads are flat ground
    height, height_source = building_height(props, report)
    material, material_source = building_material(props, height, report)
    _bump(report["height_sources"], height_source)
    _bump(report["material_sources"], material_source)
    _bump(report["materials"], material)
    return height, height_source, material, material_source


def _feature_list(doc: Any, origin: str) -> list:
    if not isinstance(doc, Mapping) or doc.get("type") not in ("FeatureCollection", "Feature"):
        raise SceneFileError(
            f"{origin}: not a GeoJSON FeatureCollection",
            hint='give a GeoJSON file whose top level is {"type": "FeatureCollection", '
            '"features": [...]} (EPSG:4326 lon/lat)',
        )
    if doc["type"] == "Feature":
        return [doc]
    features = doc.get("features")
    if not isinstance(features, list):
        raise SceneFileError(
            f"{origin}: the FeatureCollection has no 'features' list",
            hint="add a 'features' array of GeoJSON Feature objects",
        )
    return features


def _check_geojson_crs(doc: Mapping[str, Any], origin: str) -> None:
    """Reject files that declare (old-style GeoJSON ``crs`` member) a CRS other than lon/lat WGS 84."""
    crs = doc.get("crs")
    name = crs.get("properties", {}).get("name", "") if isinstance(crs, Mapping) else ""
    if name and not re.search(r"(CRS84|EPSG:{1,2}4326)$", str(name)):
        raise SceneFileError(
            f"{origin}: declares crs {name!r}; footprints must be lon/lat (EPSG:4326)",
            hint=f"reproject it, e.g. ogr2ogr -t_srs EPSG:4326 out.geojson {origin}",
        )


def _empty_error(origin: str, box: LonLatBox, report: dict, bounds: list) -> FootprintsEmptyError:
    where = f"box west {box.west} south {box.south} east {box.east} north {box.north}"
    if bounds and report["skipped"].get("not_lonlat", 0) == 0:
        arr = np.array(bounds)
        span = (
            f"; its footprints span lon {arr[:, 0].min():.5f}..{arr[:, 2].max():.5f}, "
            f"lat {arr[:, 1].min():.5f}..{arr[:, 3].max():.5f}"
        )
    else:
        span = ""
    skipped = ", ".join(f"{k}: {v}" for k, v in sorted(report["skipped"].items()))
    hint = (
        "make sure the file covers the box and is in EPSG:4326 lon/lat, and that its features carry building=*, "
        "amenity=parking or highway=* (or Overture building fields)"
    )
    if report["skipped"].get("not_lonlat"):
        hint = "its coordinates are not lon/lat degrees: reproject it, e.g. ogr2ogr -t_srs EPSG:4326 out.geojson in"
    return FootprintsEmptyError(
        f"{origin}: no building, parking or road footprint inside the {where} "
        f"({report['input_features']} features read{span}{'; skipped ' + skipped if skipped else ''})",
        hint=hint,
    )


# --- the file reader --------------------------------------------------------------------------------------------------


def _read_json_file(path: Path) -> Any:
    if not path.is_file():
        raise SceneFileError(
            f"{path}: no such footprint file",
            hint="check the path (make dataset SCENE=<city> OSM=path/to/file.osm or .geojson)",
        )
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise SceneFileError(
            f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})",
            hint="give a GeoJSON FeatureCollection in EPSG:4326 (e.g. exported from overpass-turbo or QGIS)",
        ) from None
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(
            f"{path}: cannot be read ({e})", hint="check the file's permissions and that it is UTF-8 GeoJSON"
        ) from None


def read_geojson(
    path: str | Path,
    box: LonLatBox,
    crs: str,
    *,
    source: str | None = None,
    licence: str | None = None,
    attribution: str | None = None,
    retrieved_utc: str | None = None,
) -> CityFootprints:
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
        licence = (
            licence
            or tag_text(doc.get("licence") or doc.get("license") or meta.get("licence") or meta.get("license"))
            or USER_FILE_LICENCE
        )
        attribution = attribution or tag_text(doc.get("attribution") or meta.get("attribution")) or "unknown"
    return footprints_from_geojson(
        doc,
        box,
        crs,
        source=source or f"user file {path}",
        licence=licence or "",
        attribution=attribution or "",
        retrieved_utc=retrieved_utc,
        origin=str(path),
    )
