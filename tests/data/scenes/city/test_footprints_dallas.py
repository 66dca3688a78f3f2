"""The packaged Downtown Dallas footprints (Overture / OpenStreetMap, ODbL) load offline into the local frame."""

from __future__ import annotations

import json
import re

import pytest
from shapely.geometry import LinearRing, Polygon

from dtradar_data.scenes.city.footprints import CITY_BOXES, MATERIALS, CityFootprints
from dtradar_data.scenes.city.frame import local_extent
from dtradar_data.scenes.city.packaged import (
    DALLAS_ATTRIBUTION,
    DALLAS_FILE,
    DALLAS_LICENCE,
    DALLAS_NOTICE_FILE,
    packaged_files,
    packaged_path,
)
from dtradar_data.scenes.city.sources import load_footprints
from dtradar_data.scenes.city.tags import HEIGHT_RANGE_M


@pytest.fixture(scope="module")
def dallas() -> CityFootprints:
    box, crs = CITY_BOXES["dallas"]
    return load_footprints(f"packaged:{DALLAS_FILE}", box, crs)


@pytest.fixture(scope="module")
def raw_properties() -> dict[str, dict]:
    doc = json.loads(packaged_path(DALLAS_FILE).read_text(encoding="utf-8"))
    return {f["properties"]["id"]: f["properties"] for f in doc["features"]}


def test_the_dallas_file_and_its_notice_ship_with_the_package():
    assert DALLAS_FILE in packaged_files()
    notice = packaged_path(DALLAS_NOTICE_FILE).read_text(encoding="utf-8")
    assert DALLAS_ATTRIBUTION in notice and "ODbL-1.0" in notice


def test_all_64_buildings_of_the_file_intersect_the_box_and_13_straddle_its_edge(dallas):
    assert dallas.counts() == {"building": 64, "parking": 0, "road": 0}
    assert dallas.report["input_features"] == 64
    assert dallas.report["clipped"]["building"] == 13
    assert dallas.report["dropped_outside"]["building"] == 0 and dallas.report["skipped"] == {}


def test_dallas_carries_its_licence_attribution_and_source(dallas):
    assert dallas.licence == DALLAS_LICENCE == "ODbL-1.0"
    assert dallas.attribution == "(c) OpenStreetMap contributors, Overture Maps Foundation, ODbL"
    assert DALLAS_FILE in dallas.source and dallas.retrieved_utc is None and dallas.crs == "EPSG:32614"


def test_heights_are_positive_and_come_from_overture_height_wherever_it_is_given(dallas, raw_properties):
    lo, hi = HEIGHT_RANGE_M
    for feature in dallas.features:
        assert lo <= feature.height_m <= hi
        props = raw_properties[feature.source_id]
        if props["overture_height"] is not None:
            assert feature.height_source == "overture_height"
            assert feature.height_m == pytest.approx(props["overture_height"], abs=1e-3)
        elif props["num_floors"] is not None:
            assert feature.height_source == "num_floors"
            assert feature.height_m == pytest.approx(3.5 * props["num_floors"])
        else:
            assert feature.height_source == "default"
    assert dallas.report["height_sources"] == {"overture_height": 54, "num_floors": 5, "default": 5}


def test_materials_follow_the_height_rule_and_garages_are_concrete(dallas):
    assert {f.material for f in dallas.features} <= set(MATERIALS)
    assert all(f.material_source == "rule" for f in dallas.features)
    for feature in dallas.features:
        if feature.subtype == "parking":
            assert feature.material == "concrete"
        elif feature.height_m >= 60:
            assert feature.material == "glass"
        elif feature.height_m >= 25:
            assert feature.material == "concrete"
        else:
            assert feature.material == "brick"
    assert dallas.report["materials"] == {"concrete": 26, "glass": 17, "brick": 21}


def test_coordinates_lie_within_the_local_box_extent(dallas):
    hx, hy = local_extent(*CITY_BOXES["dallas"])
    assert hx == pytest.approx(217.8, abs=0.5) and hy == pytest.approx(268.4, abs=0.5)
    for feature in dallas.features:
        for x, y in feature.exterior:
            assert abs(x) <= hx + 1e-6 and abs(y) <= hy + 1e-6


def test_rings_are_open_valid_and_exteriors_counter_clockwise(dallas):
    for feature in dallas.features:
        assert feature.exterior[0] != feature.exterior[-1] and len(feature.exterior) >= 3
        assert LinearRing(feature.exterior).is_ccw
        assert all(not LinearRing(h).is_ccw for h in feature.holes)
        assert Polygon(feature.exterior, feature.holes).is_valid


def test_names_are_unique_numbered_and_ordered_by_source_id(dallas):  # Overture ids sort as text
    names = [f.name for f in dallas.features]
    assert len(set(names)) == len(names) and all(re.fullmatch(r"[a-z0-9_]+", n) for n in names)
    assert names[0] == "building_000" and names[-1] == "building_063"
    assert [f.source_id for f in dallas.features] == sorted(f.source_id for f in dallas.features)


def test_two_loads_give_equal_footprints_and_the_same_hash(dallas):
    again = load_footprints(f"packaged:{DALLAS_FILE}", *CITY_BOXES["dallas"])
    assert again == dallas and again.content_hash() == dallas.content_hash()


def test_footprints_survive_a_json_round_trip(dallas):
    text = json.dumps(dallas.to_dict())
    assert CityFootprints.from_dict(json.loads(text)) == dallas
