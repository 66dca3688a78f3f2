"""City scenes: the quadrants tile the paper's box, each with its transmitter in the open; dynamic vehicles are placed
reproducibly on the roads; bad city files fail clearly. No ray tracer needed."""

from __future__ import annotations

import math

import numpy as np
import pytest
import tomllib
from shapely.geometry import Point, Polygon

from dtradar_data.core.errors import SceneFileError, UnknownNameError
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.scenes import available_scenes, build_targets, load_scene_spec
from dtradar_data.scenes.city.document import parse_city
from dtradar_data.scenes.city.reader import city_file, city_spec
from dtradar_data.scenes.city.streets import Road, find_roads, place_vehicles, quadrant_rect

QUADRANTS = ("q1", "q2", "q3", "q4")
PAPER_TX = {
    "q1": (-170.0, -92.0, 18.0),
    "q2": (-165.0, 74.0, 18.0),
    "q3": (205.0, 159.0, 18.0),
    "q4": (70.0, -170.0, 18.0),
}  # DT-RaDaR Table III


@pytest.fixture(scope="module")
def dallas():
    return {q: load_scene_spec(f"dallas-{q}", "blueprint") for q in QUADRANTS}


def _buildings(spec):
    return [Polygon(p.exterior, p.holes) for p in spec.prisms if p.kind == "building"]


def test_every_city_quadrant_is_a_builtin_scene_and_a_city_builds_its_quadrants_and_dynamic_twin():
    assert {f"{c}-{q}" for c in ("dallas", "houston") for q in QUADRANTS} <= set(available_scenes())
    assert build_targets("dallas") == [
        ("dallas-q1", "blueprint"),
        ("dallas-q2", "blueprint"),
        ("dallas-q3", "blueprint"),
        ("dallas-q4", "blueprint"),
        ("dallas-q3", "dynamic"),
    ]
    assert build_targets("houston", "dynamic") == [("houston-q2", "dynamic")]
    assert build_targets("dallas-q1") == [("dallas-q1", "blueprint")]


def test_the_quadrant_grids_tile_the_box_around_its_centre_without_overlap(dallas):
    cells = {}
    for q, spec in dallas.items():
        g = spec.grid
        assert (g.cell_m, spec.rx_height_m, spec.robot_height_m) == (4.0, 1.5, 1.5)
        x0, y0, x1, y1 = g.bounds()
        sx, sy = {"q1": (-1, -1), "q2": (-1, 1), "q3": (1, 1), "q4": (1, -1)}[q]
        assert (x0 if sx > 0 else x1) == pytest.approx(0) and (y0 if sy > 0 else y1) == pytest.approx(0)
        rect = quadrant_rect(q, 217.843, 268.413)
        assert rect.buffer(1e-6).contains(Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)]))
        xs, ys = g.centres()
        cells[q] = {(round(x, 3), round(y, 3)) for x in xs for y in ys}
    assert sum(len(c) for c in cells.values()) == len(set().union(*cells.values()))


def test_every_quadrant_shares_the_city_and_has_the_papers_transmitter_height_in_the_open(dallas):
    digests = {tuple(p.to_dict().items().__repr__() for p in s.prisms) for s in dallas.values()}
    assert len(digests) == 1 and len(dallas["q1"].prisms) == 64  # the whole city in every quadrant
    for q, spec in dallas.items():
        x, y, z = spec.tx.position_m
        assert z == PAPER_TX[q][2]
        assert quadrant_rect(q, 217.843, 268.413).contains(Point(x, y))
        assert min(Point(x, y).distance(b) for b in _buildings(spec)) >= 3.0 - 1e-6
        moved = spec.provenance["tx"]["moved_m"]
        assert moved == pytest.approx(math.dist(PAPER_TX[q][:2], (x, y)), abs=1e-3)
        assert moved < 30  # the nearest open street point, not somewhere across the quadrant


def test_cells_mostly_covered_by_buildings_are_blocked_and_open_streets_are_free(dallas):
    spec = dallas["q3"]
    blocked = occupancy(spec)
    xs, ys = spec.grid.centres()
    h = spec.grid.cell_m / 2
    buildings = _buildings(spec)
    for iy in range(0, spec.grid.ny, 5):
        for ix in range(0, spec.grid.nx, 5):
            cell = Polygon(
                [(xs[ix] - h, ys[iy] - h), (xs[ix] + h, ys[iy] - h), (xs[ix] + h, ys[iy] + h), (xs[ix] - h, ys[iy] + h)]
            )
            share = sum(cell.intersection(b).area for b in buildings) / cell.area
            if share >= 0.5 + 1e-6:
                assert blocked[iy, ix]
            elif share < 0.5 - 1e-6:
                assert not blocked[iy, ix]
    assert 0.3 < blocked.mean() < 0.7


def test_the_dynamic_twin_adds_the_papers_vehicles_on_the_roads_reproducibly():
    a = load_scene_spec("dallas-q3", "dynamic")
    b = load_scene_spec("dallas-q3", "dynamic")
    assert a.digest() == b.digest()
    vehicles = [o for o in a.objects if o.kind in ("car", "bus")]
    assert sorted(o.kind for o in vehicles) == ["bus"] * 5 + ["car"] * 5
    assert all(o.mesh == "sionna:low_poly_car" for o in vehicles if o.kind == "car")
    roads = [Road(r["name"], tuple(r["from_m"]), tuple(r["to_m"])) for r in a.provenance["dynamic"]["roads"]]
    buildings = _buildings(a)
    for v in vehicles:
        assert min(r.line.distance(Point(v.x_m, v.y_m)) for r in roads) == pytest.approx(1.75, abs=1e-3)
        footprint = Polygon(v.corners())
        assert not any(footprint.intersects(b) for b in buildings)
    blueprint = occupancy(load_scene_spec("dallas-q3", "blueprint"))
    dynamic = occupancy(a)
    assert (dynamic & ~blueprint).sum() >= 10 and not (blueprint & ~dynamic).any()


def test_another_seed_places_the_vehicles_elsewhere_and_the_same_seed_the_same_way():
    spec = load_scene_spec("dallas-q3", "blueprint")
    roads = [Road("a", (0.0, 74.7), (217.8, 135.1)), Road("b", (0.0, 164.0), (217.8, 224.4))]
    rect = quadrant_rect("q3", 217.843, 268.413)
    one = place_vehicles(roads, {"car": 5, "bus": 5}, 0, _buildings(spec), rect)
    again = place_vehicles(roads, {"car": 5, "bus": 5}, 0, _buildings(spec), rect)
    other = place_vehicles(roads, {"car": 5, "bus": 5}, 1, _buildings(spec), rect)
    assert one == again and one != other


def test_roads_found_automatically_run_through_open_streets():
    spec = load_scene_spec("dallas-q3", "blueprint")
    rect = quadrant_rect("q3", 217.843, 268.413)
    roads = find_roads(_buildings(spec), rect)
    assert len(roads) == 2
    for r in roads:
        assert r.line.length >= 60 and min(r.line.distance(b) for b in _buildings(spec)) >= 7 - 1e-6


def test_only_the_dynamic_quadrant_has_a_dynamic_twin():
    with pytest.raises(UnknownNameError, match="dallas-q3/dynamic"):
        load_scene_spec("dallas-q1", "dynamic")


def test_a_finer_cell_size_from_the_command_line_refines_the_grid():
    spec = load_scene_spec("dallas-q3", "blueprint", cell_m=2.0)
    assert (spec.grid.cell_m, spec.grid.nx, spec.grid.ny) == (2.0, 108, 134)
    with pytest.raises(SceneFileError, match="larger than the quadrant"):
        load_scene_spec("dallas-q3", "blueprint", cell_m=500.0)
    with pytest.raises(SceneFileError, match="city scenes only"):
        load_scene_spec("cubicle", "blueprint", cell_m=2.0)


def test_the_card_facts_of_a_quadrant_are_in_its_provenance():
    spec = load_scene_spec("dallas-q2", "blueprint")
    fp = spec.provenance["footprints"]
    assert spec.licence == "ODbL-1.0" and "OpenStreetMap" in spec.attribution
    assert fp["counts"] == {"building": 64, "parking": 0, "road": 0} and len(fp["content_hash"]) == 64
    assert "provenance" not in spec.to_dict() and "prisms" in spec.to_dict()


def _dallas_doc(**changes):
    data = tomllib.loads(city_file("dallas").read_text())
    for dotted, value in changes.items():
        *path, key = dotted.split(".")
        node = data
        for p in path:
            node = node[p]
        if value is None:
            node.pop(key)
        else:
            node[key] = value
    return data


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"grid.cell_m": -4.0}, r"\[grid\]: cell_m"),
        ({"grid.cel_m": 4.0}, "unknown key 'cel_m'; did you mean 'cell_m'"),
        ({"city.ground_material": "mud"}, "not an ITU material"),
        ({"quadrants.q3.tx_m": [1.0, 2.0]}, r"\[quadrants.q3\]: tx_m"),
        ({"city": None}, "missing section 'city'"),
        ({"dynamic.quadrant": "q5"}, r"\[dynamic\]: quadrant"),
    ],
)
def test_a_bad_city_file_names_the_section_and_the_field(changes, message):
    with pytest.raises(SceneFileError, match=message):
        parse_city(_dallas_doc(**changes), origin="dallas.toml")


def test_vehicles_that_do_not_fit_on_the_roads_fail_with_a_hint():
    doc = parse_city(_dallas_doc(**{"dynamic.cars": 400}))
    with pytest.raises(SceneFileError, match="could not place car"):
        city_spec(doc, "q3", "dynamic")


def test_the_houston_quadrants_build_from_a_users_osm_file(tmp_path):
    from pathlib import Path

    fixture = Path(__file__).parent / "fixtures" / "tiny_houston.osm"
    spec = load_scene_spec("houston-q2", "dynamic", footprints=str(fixture))
    counts = spec.count_by_kind()
    assert counts["building"] >= 1 and counts["car"] == 4 and counts["bus"] == 2
    assert spec.provenance["dynamic"]["roads_from"] == "auto"
    assert spec.tx.position_m[2] == 20.0
    assert np.asarray(occupancy(spec)).shape == (spec.grid.ny, spec.grid.nx)
