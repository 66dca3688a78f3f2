"""A built version stores the scene it was traced from (Mitsuba XML and meshes) that plain Sionna opens and re-traces
to the same strongest paths; it does not move the version; a version without one loads and says how to get it; a
scene on an external XML is stored self-contained (needs Sionna for the builds)."""

import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from dtradar_data.core.errors import MissingSceneError
from dtradar_data.core.layout import SCENE_XML


def _config():
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    rt = RTSettings(max_depth=2, samples_per_src=2_000, device="cpu")
    return BuildConfig(scene="cubicle", rt=rt, coverage_map=False, progress=False)


@pytest.fixture
def small_cubicle():
    """The real cubicle blueprint (metal cubicles, wooden chairs, brick walls), cut down to a 6 x 4 cell corner."""
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec("cubicle", "blueprint")
    return replace(spec, grid=replace(spec.grid, nx=6, ny=4))


@pytest.mark.sionna
def test_plain_sionna_opens_the_stored_scene_and_retraces_the_same_strongest_path_in_every_cell(
    root, small_cubicle, tmp_path
):
    import dtradar_data
    from dtradar_data.geometry.meshes import write_mitsuba_scene
    from dtradar_data.pipeline.inputs import build_inputs
    from dtradar_data.pipeline.static_build import build_one
    from dtradar_data.rt.scene_retrace import retrace_strongest, stored_strongest, strongest_path_agreement
    from dtradar_data.store.local import verify_dir
    from dtradar_data.store.versions import version_id

    config = _config()
    built = build_one(small_cubicle, config)
    assert built.version == version_id(build_inputs(small_cubicle, config)), "the version is its inputs' hash"
    ds = dtradar_data.load("cubicle/blueprint", revision=built.version)
    xml = ds.scene_xml
    assert xml == ds.path / SCENE_XML and verify_dir(ds.path) == []
    files = sorted(f for f in ds.meta["files"] if f.startswith("scene/"))
    assert files == ["scene/meshes/brick.ply", "scene/meshes/concrete.ply", "scene/meshes/metal.ply"] + [
        "scene/meshes/wood.ply",
        "scene/scene.xml",
    ]
    # the stored files are the tracer's scene byte for byte: a function of the spec, which the version hashes
    again = write_mitsuba_scene(small_cubicle, tmp_path / "again")
    for name in files:
        assert (ds.path / name).read_bytes() == (again.parent / name.removeprefix("scene/")).read_bytes(), name
    card = (ds.path / "README.md").read_text()
    assert "scene/scene.xml" in card and "load_scene" in card, "the card names the scene and how to open it"

    agreement = strongest_path_agreement(stored_strongest(ds), retrace_strongest(ds))
    assert agreement["cells"] == 24 and agreement["cells_with_paths"] == 24
    assert agreement["fraction"] >= 0.99, agreement


def test_a_version_without_a_scene_loads_unchanged_and_says_to_build_it_again(root):
    import dtradar_data

    ds = _stored_without_scene()
    loaded = dtradar_data.load(ds.name, revision=ds.version)
    assert loaded.table.equals(ds.table)
    with pytest.raises(MissingSceneError, match="stores no scene") as caught:
        _ = loaded.scene_xml
    hint = caught.value.hint
    assert f"rm -r {loaded.path}" in hint and "python -m dtradar_data build --scene" in hint
    assert "same version" in hint
    with pytest.raises(MissingSceneError, match="in memory"):
        _ = dtradar_data.Dataset.from_table(ds.table, ds.meta).scene_xml


def _stored_without_scene():
    """A small version written as builds wrote them before they stored the scene (its files: the tables only)."""
    from dtradar_data.pipeline.synthetic import synthetic_dataset
    from dtradar_data.store import local, writing

    ds = synthetic_dataset(name="cubicle/blueprint")
    path = writing.write_version("cubicle/blueprint", "0123456789abcdef", ds.table, dict(ds.meta))
    return local.load("cubicle/blueprint", revision=path.name)


def test_a_damaged_scene_file_is_named(root, tmp_path):
    from dtradar_data.core.errors import CorruptDatasetError
    from dtradar_data.pipeline.synthetic import synthetic_dataset
    from dtradar_data.store import local, writing

    ds = synthetic_dataset(name="cubicle/blueprint")
    xml = tmp_path / "scene.xml"
    xml.write_text('<scene version="2.1.0"/>\n')
    extra = {SCENE_XML: xml}
    path = writing.write_version("cubicle/blueprint", "0123456789abcdef", ds.table, dict(ds.meta), extra_files=extra)
    loaded = local.load("cubicle/blueprint", revision=path.name)
    assert loaded.scene_xml.read_text() == xml.read_text()
    (path / SCENE_XML).write_text("changed")
    with pytest.raises(CorruptDatasetError, match="scene.xml"):
        _ = loaded.scene_xml
    assert any("scene/scene.xml" in p for p in local.verify_dir(path))


@pytest.mark.parametrize("name", ["../meta.json", "scene/../x", "scene/.hidden", "other/x.ply"])
def test_extra_files_outside_the_scene_folder_are_refused(root, tmp_path, name):
    from dtradar_data.pipeline.synthetic import synthetic_dataset
    from dtradar_data.store import writing

    ds = synthetic_dataset(name="cubicle/blueprint")
    src = tmp_path / "f"
    src.write_text("x")
    with pytest.raises(writing.InvalidTableError, match="not a plain file name"):
        writing.write_version("cubicle/blueprint", "0123456789abcdef", ds.table, dict(ds.meta), extra_files={name: src})


def _canyon_scene(tmp_path: Path) -> dict[str, Path]:
    """Sionna's street canyon as a user's XML, stored as a build stores it; then the user's folder is moved away."""
    from dtradar_data.geometry.scene_files import write_stored_scene
    from dtradar_data.scenes import load_scene_spec
    from dtradar_data.scenes.sionna_scenes import sionna_xml

    shutil.copytree(sionna_xml("simple_street_canyon").parent, tmp_path / "canyon")
    xml = tmp_path / "canyon" / "simple_street_canyon.xml"
    spec = load_scene_spec(xml, "blueprint", grid=(-20.0, -4.0, 4.0, 11, 3), tx=(0.0, 0.0, 20.0))
    stored = write_stored_scene(spec, tmp_path / "stored")
    shutil.move(tmp_path / "canyon", tmp_path / "moved")  # the stored copy no longer needs the user's folder
    return stored


def test_a_scene_on_an_external_xml_is_stored_self_contained(tmp_path):
    stored = _canyon_scene(tmp_path)
    text = (tmp_path / "stored" / "scene.xml").read_text()
    assert str(tmp_path) not in text and 'value="base/meshes/' in text and "sha256" in text
    for name, path in stored.items():
        assert name.startswith("scene/") and path.is_file()
    assert "scene/scene.xml" in stored and sum(n.startswith("scene/base/") for n in stored) >= 2


@pytest.mark.sionna
def test_plain_sionna_opens_a_stored_scene_on_an_external_xml(tmp_path):
    from dtradar_data.rt.tracer import _import_sionna

    _canyon_scene(tmp_path)
    _, rt = _import_sionna("cpu", cpu_only=True)
    scene = rt.load_scene(str(tmp_path / "stored" / "scene.xml"), merge_shapes=False)
    assert len(scene.objects) >= 2 and "floor" in scene.objects  # Sionna drops the "mesh-" of an id
