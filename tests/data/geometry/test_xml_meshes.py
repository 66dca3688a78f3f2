"""Geometry of XML scenes: occupancy from the meshes at robot height, the ground, floor plans, the tracer's XML."""

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from dtradar_data.geometry.floorplan import save_floorplan_png
from dtradar_data.geometry.meshes import write_mitsuba_scene
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.geometry.xml_meshes import base_footprints, ground_height
from dtradar_data.scenes import load_scene_spec


def canyon(**opts):
    return load_scene_spec("sionna:simple_street_canyon", "blueprint", **opts)


def test_occupancy_of_the_street_canyon_blocks_the_buildings_and_leaves_the_street_free():
    spec = canyon()
    blocked = occupancy(spec)
    xs, ys = spec.grid.centres()
    street = np.abs(ys) < 7  # the street between the blocks runs along x, about y in [-8.6, 9.6]
    inside = (np.abs(ys) > 12) & (np.abs(ys) < 35)
    cols = np.abs(xs) < 14  # the middle blocks span about x in [-15, 16]
    assert not blocked[street].any()  # the floor never blocks
    assert blocked[np.ix_(inside, cols)].all()
    assert 0.3 < blocked.mean() < 0.7
    assert len(base_footprints(spec)) == 6  # six buildings, the floor is not one


def test_a_sloped_ground_carries_the_receivers_and_transforms_are_applied(tmp_path):
    # A 40 m square ground tilted 10 degrees about y, and a 4 m cube standing on it: Mitsuba primitives, no meshes.
    xml = tmp_path / "slope.xml"
    xml.write_text("""<scene version="2.1.0">
  <bsdf type="itu-radio-material" id="itu_concrete"><string name="type" value="concrete"/></bsdf>
  <shape type="rectangle" id="ground"><transform name="to_world"><scale value="20"/><rotate y="1" angle="-10"/>
  </transform><ref id="itu_concrete"/></shape>
  <shape type="cube" id="block"><transform name="to_world"><scale value="2"/><translate x="5" y="0" z="2.5"/>
  </transform><ref id="itu_concrete"/></shape>
</scene>""")
    spec = load_scene_spec(xml, "blueprint", grid=(-19, -20, 4, 10, 11), tx=(0, 0, 20))
    assert spec.base.ground == ("ground",)
    z = ground_height(spec, [-10.0, 0.0, 10.0], [0.0, 0.0, 0.0])
    assert np.allclose(z, np.tan(np.radians(10)) * np.array([-10, 0, 10]), atol=1e-6)
    blocked = occupancy(spec)
    assert blocked.sum() == 1 and blocked[spec.grid.index_of(5.0, 0.0)[::-1]]


def test_the_floor_plan_draws_the_footprints(tmp_path):
    out = save_floorplan_png(canyon(), tmp_path / "plan.png", label=False, dpi=60)
    assert out.stat().st_size > 5_000


def test_the_tracer_xml_keeps_the_bundled_shapes_with_absolute_mesh_paths(tmp_path):
    spec = canyon()
    xml = write_mitsuba_scene(spec, tmp_path / "scene")
    root = ET.parse(xml).getroot()
    files = [s.get("value") for s in root.iter("string") if s.get("name") == "filename"]
    assert len(files) == 7 and all(Path(f).is_absolute() and Path(f).is_file() for f in files)
    assert {b.get("id") for b in root.findall("bsdf")} == {"glass", "wood", "marble", "brick", "concrete"}
