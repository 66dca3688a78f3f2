"""A scene file the tracer could not take is refused when it is read, before the build makes a work folder, a lock
or anything else in the data root: nothing is traced and the data root stays empty."""

import pytest

from dtradar_data.core.errors import SceneFileError
from dtradar_data.pipeline import builder
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.rt import tracer

TWO_ARRAYS = """[[tx]]
name = "ap1"
position_m = [1.0, 0.75, 2.4]

[[tx]]
name = "ap2"
position_m = [1.5, 0.75, 2.4]
num_rows = 4
"""


@pytest.fixture
def no_tracer(monkeypatch):
    def refuse(self, *args, **kwargs):
        raise AssertionError("a ray tracer was made for a scene that must be refused before")

    monkeypatch.setattr(tracer.RayTracer, "__init__", refuse)


@pytest.mark.parametrize("variant", ["blueprint", "all"])
def test_a_room_whose_transmitters_have_two_arrays_is_refused_before_its_work_folder_exists(
    root, tmp_path, tiny_room, no_tracer, variant
):
    room = tiny_room.replace("[tx]\nposition_m = [1.0, 0.75, 2.4]\n", TWO_ARRAYS)
    if variant == "all":
        room += '[dynamic]\ndescription = "nothing moved"\n'
    path = tmp_path / "tiny-room.toml"
    path.write_text(room)
    with pytest.raises(SceneFileError) as err:
        builder.build(BuildConfig(scene=str(path), variant=variant, progress=False))
    text = str(err.value)
    assert "[[tx]] 'ap2' has another array than [[tx]] 'ap1' (4x2 tr38901 VH vs 8x2 tr38901 VH)" in text
    assert "how to fix: give every [[tx]] the same num_rows" in text
    assert not root.exists() or not any(root.rglob("*")), sorted(root.rglob("*"))
