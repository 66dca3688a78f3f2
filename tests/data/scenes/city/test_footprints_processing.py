"""Processing of footprint sources: bad geometry, slivers, heights, materials, road widths, source dispatch, errors."""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest
from pyproj import Transformer
from shapely.geometry import LinearRing

from dtradar_data.core.errors import DtradarError, InvalidCoordinatesError, SceneFileError, UnknownNameError
from dtradar_data.scenes.city.footprints import CITY_BOXES, FootprintsEmptyError, LonLatBox
from dtradar_data.scenes.city.frame import local_transform, utm_crs_for
from dtradar_data.scenes.city.geojson import MIN_AREA_M2, read_geojson
from dtradar_data.scenes.city.sources import load_footprints
from dtradar_data.scenes.city.tags import (
    DEFAULT_HEIGHT_M,
    ROAD_WIDTH_M,
    building_height,
    building_material,
    parse_length_m,
    road_width,
)

BOX, CRS = CITY_BOXES["houston"]
_TO_LONLAT = Transformer.from_crs(CRS, "EPSG:4326", always_xy=True)
_CX, _CY = Transformer.from_crs("EPSG:4326", CRS, always_xy=True).transform(*BOX.centre)


def lonlat(x: float, y: float) -> list[float]:
    """Lon/lat of local metres (x, y) in the Houston frame (the inverse of the reader's projection)."""
    return list(_TO_LONLAT.transform(x + _CX, y + _CY))


def polygon(props: dict, ring_m: list[tuple[float, float]], fid: str) -> dict:
    ring = [lonlat(x, y) for x, y in ring_m]
    return {
        "type": "Feature",
        "properties": {"@id": fid, **props},
        "geometry": {"type": "Polygon", "coordinates": [ring + [ring[0]]]},
    }


def square(props: dict, cx: float, cy: float, side: float, fid: str) -> dict:
    h = side / 2
    return polygon(props, [(cx - h, cy - h), (cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h)], fid)


def write(tmp_path: Path, features: list[dict], name: str = "fixture.geojson") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}), encoding="utf-8")
    return path


# --- geometry -------------------------------------------------------------------------------------------------------


def test_a_self_intersecting_bow_tie_is_repaired_into_valid_parts_not_a_crash(tmp_path):
    bow_tie = polygon({"building": "yes"}, [(0, 0), (20, 20), (20, 0), (0, 20)], "way/1")
    fp = read_geojson(write(tmp_path, [bow_tie]), BOX, CRS)
    assert fp.report["repaired"] == 1
    parts = fp.of_kind("building")
    assert len(parts) == 2 and fp.report["split"] == 1  # the two triangles of the bow tie
    assert all(p.source_id == "way/1" and p.polygon().is_valid for p in parts)
    assert sum(p.polygon().area for p in parts) == pytest.approx(200.0, rel=0.01)
    assert [p.name for p in parts] == ["building_000", "building_001"]


def test_a_sliver_is_skipped_and_counted(tmp_path):
    features = [square({"building": "yes"}, 0, 0, 10, "way/1"), square({"building": "yes"}, 50, 50, 1.5, "way/2")]
    fp = read_geojson(write(tmp_path, features), BOX, CRS)
    assert [f.source_id for f in fp.features] == ["way/1"]
    assert fp.report["skipped"] == {"sliver": 1} and fp.report["skipped_ids"]["sliver"] == ["way/2"]
    assert MIN_AREA_M2 == 4.0


def test_unreadable_empty_and_point_geometries_are_skipped_with_their_reasons(tmp_path):
    features = [
        square({"building": "yes"}, 0, 0, 10, "way/1"),
        {
            "type": "Feature",
            "properties": {"@id": "way/2", "building": "yes"},
            "geometry": {"type": "Polygon", "coordinates": [[lonlat(0, 0), lonlat(1, 1)]]},
        },
        {"type": "Feature", "properties": {"@id": "way/3", "building": "yes"}, "geometry": None},
        {
            "type": "Feature",
            "properties": {"@id": "node/4", "highway": "traffic_signals"},
            "geometry": {"type": "Point", "coordinates": lonlat(5, 5)},
        },
        {
            "type": "Feature",
            "properties": {"@id": "way/5", "building": "yes"},
            "geometry": {"type": "LineString", "coordinates": [lonlat(0, 0), lonlat(30, 0)]},
        },
        square({"landuse": "grass"}, 20, 20, 10, "way/6"),
        "not a feature",
    ]
    fp = read_geojson(write(tmp_path, features), BOX, CRS)
    assert len(fp.features) == 1
    assert fp.report["skipped"] == {
        "unreadable_geometry": 1,
        "no_geometry": 1,
        "point_geometry": 1,
        "line_not_a_road": 1,
        "not_a_footprint": 2,
    }


def test_a_building_across_the_box_edge_is_clipped_and_one_outside_is_dropped(tmp_path):
    hx = 409.716
    features = [square({"building": "yes"}, hx, 0, 20, "way/1"), square({"building": "yes"}, hx + 100, 0, 20, "way/2")]
    fp = read_geojson(write(tmp_path, features), BOX, CRS)
    (clipped,) = fp.features
    assert fp.report["clipped"]["building"] == 1 and fp.report["dropped_outside"]["building"] == 1
    assert clipped.polygon().area == pytest.approx(200.0, abs=0.01)
    assert max(x for x, _ in clipped.exterior) == pytest.approx(hx, abs=1e-3)


def test_holes_are_clockwise_and_exteriors_counter_clockwise_whatever_the_input_winding(tmp_path):
    outer = [lonlat(x, y) for x, y in [(0, 0), (0, 40), (40, 40), (40, 0)]]  # clockwise on purpose
    inner = [lonlat(x, y) for x, y in [(10, 10), (30, 10), (30, 30), (10, 30)]]  # counter-clockwise on purpose
    feature = {
        "type": "Feature",
        "properties": {"@id": "way/1", "building": "yes"},
        "geometry": {"type": "Polygon", "coordinates": [outer + [outer[0]], inner + [inner[0]]]},
    }
    (f,) = read_geojson(write(tmp_path, [feature]), BOX, CRS).features
    assert LinearRing(f.exterior).is_ccw and len(f.holes) == 1 and not LinearRing(f.holes[0]).is_ccw
    assert f.exterior[0] != f.exterior[-1]


def test_highway_lines_become_road_polygons_of_their_width(tmp_path):
    def road(props, fid, y):
        return {
            "type": "Feature",
            "properties": {"@id": fid, **props},
            "geometry": {"type": "LineString", "coordinates": [lonlat(-100, y), lonlat(100, y)]},
        }

    features = [
        road({"highway": "primary", "width": "20 m"}, "way/1", 0),
        road({"highway": "secondary", "lanes": "3"}, "way/2", 100),
        road({"highway": "residential"}, "way/3", 200),
        road({"highway": "proposed"}, "way/4", 300),
        road({"highway": "primary", "tunnel": "yes"}, "way/5", -100),
    ]
    fp = read_geojson(write(tmp_path, features), BOX, CRS)
    widths = [f.polygon().area / 200.0 for f in fp.of_kind("road")]  # length 200 m plus round caps
    assert widths[0] == pytest.approx(20.0, rel=0.1) and widths[1] == pytest.approx(10.5, rel=0.1)
    assert widths[2] == pytest.approx(ROAD_WIDTH_M["residential"], rel=0.1)
    assert all(f.height_m == 0 and f.material == "concrete" for f in fp.of_kind("road"))
    assert fp.report["road_width_sources"] == {"width": 1, "lanes": 1, "default": 1}
    assert fp.report["skipped"] == {"highway_not_a_surface": 1, "tunnel": 1}


def test_parking_lots_are_flat_concrete_and_garages_are_buildings(tmp_path):
    features = [
        square({"amenity": "parking"}, 0, 0, 30, "way/1"),
        square({"amenity": "parking", "parking": "multi-storey", "building": "parking"}, 100, 0, 30, "way/2"),
        square({"amenity": "parking", "parking": "underground"}, 200, 0, 30, "way/3"),
    ]
    fp = read_geojson(write(tmp_path, features), BOX, CRS)
    (lot,), (garage,) = fp.of_kind("parking"), fp.of_kind("building")
    assert lot.height_m == 0 and lot.material == "concrete" and lot.subtype == "surface"
    assert garage.material == "concrete" and garage.height_m == DEFAULT_HEIGHT_M
    assert fp.report["skipped"] == {"underground_parking": 1}


def test_output_does_not_depend_on_input_order(tmp_path):
    features = [
        square({"building": "yes", "height": str(10 + i)}, -300 + 60 * i, 0, 20, f"way/{i * 7 + 3}") for i in range(10)
    ]
    first = read_geojson(write(tmp_path, features, "a.geojson"), BOX, CRS)
    random.Random(0).shuffle(features)
    second = read_geojson(write(tmp_path, features, "b.geojson"), BOX, CRS, source=first.source)
    assert first.features == second.features
    assert [f.source_id for f in first.features][:3] == ["way/3", "way/10", "way/17"]  # numeric, not text, order


# --- heights and materials ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "metres"),
    [
        ("45", 45.0),
        ("45 m", 45.0),
        ("45m", 45.0),
        ("45.5 metres", 45.5),
        ("45,5", 45.5),
        ("150 ft", 45.72),
        ("12'6\"", 3.81),
        ("45;50", 45.0),
        (30, 30.0),
        ("tall", None),
        ("", None),
        (None, None),
    ],
)
def test_lengths_parse_with_their_units(text, metres):
    value = parse_length_m(text)
    assert value == (None if metres is None else pytest.approx(metres, abs=1e-3))


@pytest.mark.parametrize(
    ("props", "height", "source"),
    [
        ({"height": "45 m", "building:levels": "3"}, 45.0, "height"),
        ({"height": "150 ft"}, 45.72, "height"),
        ({"building:levels": "5"}, 17.5, "building:levels"),
        ({"height": "tall", "building:levels": "4"}, 14.0, "building:levels"),
        ({"overture_height": 47.4, "num_floors": 10}, 47.4, "overture_height"),
        ({"overture_height": None, "num_floors": 10}, 35.0, "num_floors"),
        ({"building": "yes"}, DEFAULT_HEIGHT_M, "default"),
        ({"height": "5000"}, 600.0, "height"),
    ],
)
def test_heights_come_from_height_then_levels_then_overture_then_the_default(props, height, source):
    assert building_height(props) == (pytest.approx(height, abs=1e-3), source)


@pytest.mark.parametrize(
    ("props", "height", "material", "source"),
    [
        ({"building:material": "brick"}, 100.0, "brick", "tag:building:material"),
        ({"building:material": "sandstone"}, 10.0, "marble", "tag:building:material"),
        ({"building:facade:material": "glass"}, 10.0, "glass", "tag:building:facade:material"),
        ({"building:material": "metal"}, 10.0, "glass", "tag:building:material"),
        ({"building:material": "reinforced_concrete"}, 80.0, "concrete", "tag:building:material"),
        ({"building:material": "wood"}, 10.0, "brick", "rule"),
        ({}, 75.0, "glass", "rule"),
        ({}, 60.0, "glass", "rule"),
        ({}, 30.0, "concrete", "rule"),
        ({}, 24.9, "brick", "rule"),
        ({"building_class": "parking"}, 80.0, "concrete", "rule"),
    ],
)
def test_materials_come_from_the_material_tag_else_the_height_rule(props, height, material, source):
    assert building_material(props, height) == (material, source)


def test_the_report_counts_height_and_material_sources_and_unparsed_values(tmp_path):
    features = [
        square({"building": "yes", "height": "20 m"}, 0, 0, 10, "way/1"),
        square({"building": "yes", "building:levels": "20"}, 50, 0, 10, "way/2"),
        square({"building": "yes", "height": "n/a", "building:material": "wood"}, 100, 0, 10, "way/3"),
    ]
    r = read_geojson(write(tmp_path, features), BOX, CRS).report
    assert r["height_sources"] == {"height": 1, "building:levels": 1, "default": 1}
    assert r["height_unparsed"] == {"height": 1}
    assert r["material_sources"] == {"rule": 3} and r["materials"] == {"brick": 2, "glass": 1}
    assert r["material_tags_unmapped"] == {"building:material=wood": 1}


def test_road_widths_come_from_width_then_lanes_then_the_type_default():
    assert road_width({"highway": "primary", "width": "9", "lanes": "4"}) == (9.0, "width")
    assert road_width({"highway": "primary", "lanes": "4"}) == (14.0, "lanes")
    assert road_width({"highway": "footway"}) == (ROAD_WIDTH_M["footway"], "default")


# --- frame, sources and errors --------------------------------------------------------------------------------------


def test_boxes_are_built_from_lat_lon_corners_and_reject_swapped_ones():
    box = LonLatBox.from_corners(nw=(29.75959, -95.37055), se=(29.75249, -95.36208))
    assert box == BOX and box.bbox == (-95.37055, 29.75249, -95.36208, 29.75959)
    with pytest.raises(InvalidCoordinatesError, match="from_corners takes"):
        LonLatBox.from_corners(nw=(-95.37055, 29.75959), se=(-95.36208, 29.75249))


def test_the_local_frame_is_centred_on_the_box_and_the_crs_must_fit_it():
    x, y = local_transform(BOX, CRS)(*BOX.centre)
    assert abs(x) < 1e-6 and abs(y) < 1e-6
    assert utm_crs_for(BOX) == "EPSG:32615" and utm_crs_for(CITY_BOXES["dallas"][0]) == "EPSG:32614"
    with pytest.raises(InvalidCoordinatesError, match="EPSG:32615"):
        local_transform(BOX, "EPSG:32614")
    with pytest.raises(SceneFileError, match="projected"):
        local_transform(BOX, "EPSG:4326")
    with pytest.raises(SceneFileError, match="pyproj"):
        local_transform(BOX, "EPSG:not-a-code")


def test_a_missing_file_or_an_unsupported_type_is_a_typed_error_with_the_path(tmp_path):
    with pytest.raises(SceneFileError, match="no such footprint file") as missing:
        load_footprints(tmp_path / "nowhere.geojson", BOX, CRS)
    assert "nowhere.geojson" in str(missing.value) and "OSM=path/to" in str(missing.value)
    (tmp_path / "city.shp").write_bytes(b"")
    with pytest.raises(SceneFileError, match="unsupported footprint file type '.shp'") as unsupported:
        load_footprints(tmp_path / "city.shp", BOX, CRS)
    assert ".geojson" in str(unsupported.value) and ".osm" in str(unsupported.value)


def test_malformed_json_and_non_collections_are_typed_errors(tmp_path):
    (tmp_path / "broken.geojson").write_text("{", encoding="utf-8")
    with pytest.raises(SceneFileError, match="not valid JSON"):
        load_footprints(tmp_path / "broken.geojson", BOX, CRS)
    (tmp_path / "list.json").write_text("[]", encoding="utf-8")
    with pytest.raises(SceneFileError, match="not a GeoJSON FeatureCollection"):
        load_footprints(tmp_path / "list.json", BOX, CRS)


def test_a_file_with_nothing_inside_the_box_says_where_its_features_are(tmp_path):
    far = square({"building": "yes"}, 5000, 5000, 20, "way/1")
    with pytest.raises(FootprintsEmptyError, match="no building, parking or road footprint inside") as err:
        load_footprints(write(tmp_path, [far]), BOX, CRS)
    assert "span lon -95.31" in str(err.value) and isinstance(err.value, SceneFileError)


def test_a_file_in_projected_metres_is_told_to_reproject(tmp_path):
    utm = {
        "type": "Feature",
        "properties": {"building": "yes"},
        "geometry": {
            "type": "Polygon",
            "coordinates": [[[271000, 3293000], [271020, 3293000], [271020, 3293020], [271000, 3293000]]],
        },
    }
    with pytest.raises(FootprintsEmptyError, match="not lon/lat degrees"):
        load_footprints(write(tmp_path, [utm]), BOX, CRS)


def test_an_unknown_packaged_name_suggests_the_right_one():
    with pytest.raises(UnknownNameError, match="did you mean") as err:
        load_footprints("packaged:dallas_downtown_buildings_overture.json", *CITY_BOXES["dallas"])
    assert isinstance(err.value, DtradarError)
