"""A user's scene file cannot take a built-in scene's name: a room, mesh-scene or city file whose [scene] name (or an
XML file whose file name) is a built-in room, city, city quadrant, Sionna scene or antenna-pose-error twin is a
SceneFileError that says to rename it, raised when the file is read (before its meshes are hashed, before any
trace), so it never becomes a new version of the built-in (``load("cubicle/blueprint")`` returning the user's room).
The packaged files of the built-ins keep their own names."""

import pytest

from dtradar_data import cli
from dtradar_data.core.errors import SceneFileError
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.scenes import load_scene_spec, scene_file, xml_scene
from dtradar_data.scenes.city.document import read_city_file
from dtradar_data.scenes.city.reader import city_file
from dtradar_data.scenes.names import reserved_because

RESERVED = ["cubicle", "meeting", "dallas", "houston", "dallas-q3", "houston-q1", "sionna-munich", "sionna-mine"]


@pytest.fixture()
def nothing_read(monkeypatch):
    """Tracing or reading an XML scene's meshes fails the test: the name is checked first."""

    def expensive(*args, **kwargs):
        raise AssertionError("an expensive step ran for a scene whose name should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", expensive)
    monkeypatch.setattr(static_build, "RayTracer", expensive)
    monkeypatch.setattr(xml_scene, "mesh_scene", expensive)


def room_named(tmp_path, tiny_room, name, file="room.toml"):
    path = tmp_path / file
    path.write_text(tiny_room.replace('name = "tiny-room"', f'name = "{name}"'))
    return path


@pytest.mark.parametrize("name", RESERVED)
def test_a_user_room_with_a_built_in_name_is_refused_with_a_rename_hint(tmp_path, tiny_room, nothing_read, name):
    path = room_named(tmp_path, tiny_room, name)
    with pytest.raises(SceneFileError, match=f"'{name}'") as err:
        load_scene_spec(path, "blueprint")
    assert str(path) in str(err.value) and "rename" in err.value.hint


def test_the_build_command_exits_2_and_the_built_in_stays_untouched(root, tmp_path, tiny_room, nothing_read, capsys):
    path = room_named(tmp_path, tiny_room, "cubicle")
    assert cli.main(["build", "--scene", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "'cubicle'" in err and "rename" in err and "Traceback" not in err
    assert not root.exists()


def test_a_pose_twin_name_is_refused_too(tmp_path, tiny_room, nothing_read):
    with pytest.raises(SceneFileError, match="-txpose"):
        load_scene_spec(room_named(tmp_path, tiny_room, "cubicle-txpose"), "blueprint")


def test_a_mesh_scene_file_with_a_built_in_name_is_refused_before_its_meshes_are_read(tmp_path, nothing_read):
    path = tmp_path / "mine.toml"
    path.write_text(
        'format = 1\n[scene]\nname = "meeting"\ntitle = "mine"\n[xml]\npath = "sionna:munich"\n'
        "[grid]\nx0_m = 0\ny0_m = 0\ncell_m = 1\nnx = 2\nny = 2\n[tx]\nposition_m = [0, 0, 5]\n"
    )
    with pytest.raises(SceneFileError, match="'meeting'"):
        load_scene_spec(path, "blueprint")


@pytest.mark.parametrize("stem", ["cubicle", "sionna-munich", "dallas-q2", "Meeting"])
def test_an_xml_file_named_like_a_built_in_is_refused_before_its_meshes_are_read(tmp_path, nothing_read, stem):
    xml = tmp_path / f"{stem}.xml"
    xml.write_text("<scene version='2.1.0'></scene>")
    with pytest.raises(SceneFileError, match="rename the .xml file"):
        load_scene_spec(xml, "blueprint", grid=(0, 0, 1, 2, 2), tx=(0, 0, 5))


def test_a_user_city_file_cannot_claim_a_built_in_city_or_quadrant(tmp_path):
    text = city_file("dallas").read_text()
    mine = tmp_path / "dallas.toml"
    mine.write_text(text)
    with pytest.raises(SceneFileError, match="built-in city 'dallas'"):
        read_city_file(mine)
    # a city named "sionna" would make the quadrants sionna-q1 ...: a derived name is checked like its own
    mine.write_text(text.replace('name = "dallas"', 'name = "sionna"', 1))
    with pytest.raises(SceneFileError, match="sionna-q"):
        read_city_file(mine)


def test_the_packaged_files_keep_their_built_in_names():
    assert load_scene_spec(scene_file("cubicle"), "blueprint").scene == "cubicle"
    assert read_city_file(city_file("dallas")).scene.name == "dallas"
    assert load_scene_spec("meeting", "dynamic").scene == "meeting"


def test_a_name_of_ones_own_is_free(tmp_path, tiny_room):
    assert load_scene_spec(room_named(tmp_path, tiny_room, "my-cubicle"), "blueprint").scene == "my-cubicle"
    assert reserved_because("my-cubicle") is None and reserved_because("dallas-downtown") is None


def test_a_user_file_whose_name_starts_like_a_sionna_scene_is_still_a_file(tmp_path, tiny_room, monkeypatch):
    monkeypatch.chdir(tmp_path)
    room_named(tmp_path, tiny_room, "my-room", file="sionna-room.toml")
    assert load_scene_spec("sionna-room.toml", "blueprint").scene == "my-room"
