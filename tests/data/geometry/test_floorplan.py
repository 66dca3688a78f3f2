"""Floor plan drawing: every obstacle drawn, one legend entry per material, the TX marked, a PNG written."""

from __future__ import annotations

import pytest

from dtradar_data.geometry.floorplan import draw_floorplan, material_colour, save_floorplan_png
from dtradar_data.geometry.occupancy import footprints
from dtradar_data.scenes import load_scene_spec


@pytest.mark.parametrize("scene", ["cubicle", "meeting"])
def test_floorplan_draws_every_obstacle_with_a_legend_per_material_and_the_tx(scene):
    from matplotlib.figure import Figure

    spec = load_scene_spec(scene, "dynamic")
    ax = Figure().add_subplot()
    assert draw_floorplan(ax, spec, with_grid=True, label=True) is ax
    assert len(ax.patches) == len(footprints(spec))
    _, labels = ax.get_legend_handles_labels()
    assert sorted(labels) == sorted({b.material for b, _ in footprints(spec)} | {"TX"})
    assert len(ax.texts) == sum(b.kind != "wall" for b, _ in footprints(spec))
    x0, x1 = ax.get_xlim()
    assert x0 < 0 < spec.room.width_m < x1  # walls in view
    assert material_colour("metal") != material_colour("wood")


def test_save_floorplan_png_writes_a_png(tmp_path):
    path = save_floorplan_png(load_scene_spec("cubicle", "blueprint"), tmp_path / "plan.png", dpi=40)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
