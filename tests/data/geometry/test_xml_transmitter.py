"""An XML scene's transmitter is checked against the XML's own shapes when the scene is built, before any ray:
inside a building, under the ground or off the scene is an InvalidCoordinatesError naming the shape or the extent,
and the CLI exits 2 with nothing stored."""

from __future__ import annotations

import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_data.geometry.xml_transmitter import check_transmitter_in_mesh, mesh_shape_at
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.scenes import load_scene_spec, sionna_scene_names

CANYON = "sionna:simple_street_canyon"


def canyon(tx):
    return load_scene_spec(CANYON, "blueprint", tx=tx)


def test_the_street_canyons_default_transmitter_is_over_the_street_and_passes():
    spec = load_scene_spec(CANYON, "blueprint")
    check_transmitter_in_mesh(spec)
    assert mesh_shape_at(spec, spec.tx.position_m) is None


def test_a_transmitter_inside_a_building_names_the_shape():
    with pytest.raises(InvalidCoordinatesError, match=r"is inside the shape 'mesh-.*' of sionna:simple_street_canyon"):
        check_transmitter_in_mesh(canyon((0.0, 20.0, 5.0)))


def test_a_transmitter_under_the_ground_or_off_the_scene_says_which():
    with pytest.raises(InvalidCoordinatesError, match="under the ground"):
        check_transmitter_in_mesh(canyon((0.0, 0.0, -1.0)))
    with pytest.raises(InvalidCoordinatesError, match=r"off the scene: .* shapes span x"):
        check_transmitter_in_mesh(canyon((500.0, 0.0, 20.0)))


def test_a_build_with_the_transmitter_in_a_building_exits_2_before_tracing_and_stores_nothing(
    root, monkeypatch, capsys
):
    def expensive(*args, **kwargs):
        raise AssertionError("traced a scene whose transmitter should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", expensive)
    monkeypatch.setattr(static_build, "RayTracer", expensive)
    assert cli.main(["build", "--no-progress", "--scene", CANYON, "--tx", "0", "20", "5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "is inside the shape" in err and "--tx X Y Z" in err, err
    assert "Traceback" not in err
    assert not root.exists()


@pytest.mark.slow
@pytest.mark.parametrize("scene", [s for s in sionna_scene_names() if s != CANYON])
def test_every_bundled_sionna_scenes_default_transmitter_passes(scene):
    check_transmitter_in_mesh(load_scene_spec(scene, "blueprint"))
