"""Scenes built on a Mitsuba/Sionna XML: Sionna's bundled cities by name, a user's XML, and the small scene file."""

import shutil
from pathlib import Path

import pytest

from dtradar_data.core.errors import SceneFileError, UnknownNameError
from dtradar_data.scenes import available_scenes, build_targets, load_scene_spec
from dtradar_data.scenes.sionna_scenes import sionna_scene_names, sionna_xml

SIONNA = ["sionna:etoile", "sionna:florence", "sionna:munich", "sionna:san_francisco", "sionna:simple_street_canyon"]


def canyon_copy(tmp_path: Path) -> Path:
    """Sionna's street canyon copied to a user folder: a user's own XML with relative mesh paths."""
    src = sionna_xml("simple_street_canyon").parent
    dst = tmp_path / "canyon"
    shutil.copytree(src, dst)
    return dst / "simple_street_canyon.xml"


def test_the_five_sionna_scenes_and_the_munich_deployment_are_listed_and_resolve_to_their_bundled_xml():
    assert sionna_scene_names() == sorted([*SIONNA, "sionna:munich-10tx"])
    assert {s.replace(":", "-") for s in SIONNA} <= set(available_scenes())
    for name in [*SIONNA, "sionna:munich-10tx"]:
        spec = load_scene_spec(name, "blueprint")
        assert spec.scene == name.replace(":", "-") and spec.base.xml == name.removesuffix("-10tx")
        assert Path(spec.base.path).is_file() and len(spec.base.ground) == 1
        assert spec.grid.nx * spec.grid.ny <= 6400
        assert build_targets(name) == [(name, "blueprint")]
    cells, munich = (load_scene_spec(n, "blueprint") for n in ("sionna:munich-10tx", "sionna:munich"))
    assert len(cells.transmitters) == 10 and cells.tx == munich.tx.__class__(
        **{**vars(munich.tx), "name": cells.tx.name}
    )
    assert cells.base == munich.base and cells.grid == munich.grid


def test_a_sionna_scene_named_with_a_dash_is_the_same_scene():
    assert (
        load_scene_spec("sionna-munich", "blueprint").digest() == load_scene_spec("sionna:munich", "blueprint").digest()
    )


def test_grid_tx_and_cell_size_options_replace_the_defaults():
    spec = load_scene_spec("sionna:simple_street_canyon", "blueprint", grid=(-10, -4, 4, 6, 3), tx=(0, 0, 25))
    assert (spec.grid.nx, spec.grid.ny, spec.grid.cell_m) == (6, 3, 4.0) and spec.tx.position_m == (0.0, 0.0, 25.0)
    fine = load_scene_spec("sionna:simple_street_canyon", "blueprint", cell_m=1.0)
    assert (fine.grid.nx, fine.grid.ny) == (100, 60)


def test_an_unknown_sionna_scene_suggests_the_closest_one():
    with pytest.raises(UnknownNameError, match="did you mean 'sionna:munich'"):
        load_scene_spec("sionna:munic", "blueprint")


def test_xml_options_on_an_indoor_scene_are_refused():
    with pytest.raises(SceneFileError, match="--grid and --tx apply to XML scenes"):
        load_scene_spec("cubicle", "blueprint", tx=(1, 1, 2))


def test_the_digest_changes_when_the_xml_or_one_of_its_meshes_changes(tmp_path):
    xml = canyon_copy(tmp_path)
    opts = {"grid": (-10, -4, 4, 6, 3), "tx": (0, 0, 25)}
    before = load_scene_spec(xml, "blueprint", **opts).digest()
    moved = tmp_path / "elsewhere"
    shutil.copytree(xml.parent, moved)
    assert load_scene_spec(moved / xml.name, "blueprint", **opts).digest() == before  # content, not location
    mesh = xml.parent / "meshes" / "building_1.ply"
    mesh.write_bytes(mesh.read_bytes() + b"\n")
    after_mesh = load_scene_spec(xml, "blueprint", **opts).digest()
    xml.write_text(xml.read_text().replace('value="0.1"', 'value="0.2"', 1))
    after_xml = load_scene_spec(xml, "blueprint", **opts).digest()
    assert len({before, after_mesh, after_xml}) == 3


def test_a_user_xml_loads_from_a_small_scene_file_with_a_relative_path(tmp_path):
    xml = canyon_copy(tmp_path)
    toml = tmp_path / "canyon.toml"
    toml.write_text(f"""format = 1
[scene]
name = "my-canyon"
title = "My canyon"
[xml]
path = "canyon/{xml.name}"
[grid]
x0_m = -20.0
y0_m = -4.0
cell_m = 4.0
nx = 11
ny = 3
[tx]
position_m = [0.0, 0.0, 20.0]
""")
    spec = load_scene_spec(toml, "blueprint")
    assert spec.name == "my-canyon/blueprint" and spec.base.xml == xml.name and spec.base.ground == ("mesh-floor",)
    assert build_targets(toml) == [(toml, "blueprint")]
    assert "base" in spec.to_dict() and "base" not in load_scene_spec("cubicle", "blueprint").to_dict()


def test_a_bare_xml_needs_a_grid_and_a_transmitter(tmp_path):
    with pytest.raises(SceneFileError, match="needs a grid and a transmitter"):
        load_scene_spec(canyon_copy(tmp_path), "blueprint")


def test_a_missing_xml_is_a_scene_file_error(tmp_path):
    with pytest.raises(SceneFileError, match="no such scene file"):
        load_scene_spec(tmp_path / "nowhere.xml", "blueprint", grid=(0, 0, 1, 2, 2), tx=(0, 0, 5))
    toml = tmp_path / "s.toml"
    toml.write_text(
        'format = 1\n[scene]\nname = "s"\ntitle = "S"\n[xml]\npath = "gone.xml"\n'
        "[grid]\nx0_m = 0\ny0_m = 0\ncell_m = 1\nnx = 2\nny = 2\n[tx]\nposition_m = [0, 0, 5]\n"
    )
    with pytest.raises(SceneFileError, match=r"\[xml\] path: 'gone.xml' does not exist"):
        load_scene_spec(toml, "blueprint")


def test_an_xml_without_shapes_or_with_a_missing_mesh_is_a_scene_file_error(tmp_path):
    empty = tmp_path / "empty.xml"
    empty.write_text('<scene version="2.1.0">\n</scene>\n')
    with pytest.raises(SceneFileError, match="has no shapes"):
        load_scene_spec(empty, "blueprint", grid=(0, 0, 1, 2, 2), tx=(0, 0, 5))
    xml = canyon_copy(tmp_path)
    (xml.parent / "meshes" / "building_2.ply").unlink()
    with pytest.raises(SceneFileError, match="building_2.ply, which does not exist"):
        load_scene_spec(xml, "blueprint", grid=(0, 0, 1, 2, 2), tx=(0, 0, 5))


def test_an_xml_scene_has_no_dynamic_twin():
    with pytest.raises(SceneFileError, match="no dynamic twin"):
        load_scene_spec("sionna:munich", "dynamic")
