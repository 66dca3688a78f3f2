"""A build prints where its pictures are (Sionna's radio map, coverage.png, and the table's own, cells.png) and stores
beside the radio map a picture of the cell table itself: each transmitter's path_gain_db per cell on one dB scale,
blocked cells and cells without a path drawn as such."""

import json
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from dtradar_data.pipeline.cells_picture import BLOCKED_COLOUR, NO_PATH_COLOUR, gain_grids, render_cells_png


@pytest.fixture
def room(tmp_path, tiny_room):
    from dtradar_data.scenes import load_scene_spec

    path = tmp_path / "picture-room.toml"
    path.write_text(tiny_room.replace('name = "tiny-room"', 'name = "picture-room"'))
    return path, load_scene_spec(path, "blueprint")


def _table(nx, ny, gain):
    iy, ix = np.divmod(np.arange(nx * ny)[::-1], nx)  # rows in reverse: the picture places them by ix, iy
    return pa.table({"ix": ix, "iy": iy, "path_gain_db": pa.array(gain[iy, ix], mask=np.isnan(gain[iy, ix]))})


def _colour_share(png, colour: str) -> float:
    import matplotlib.colors
    import matplotlib.image

    rgb = matplotlib.image.imread(png)[..., :3]
    return float(np.all(np.abs(rgb - np.array(matplotlib.colors.to_rgb(colour))) < 0.02, axis=-1).mean())


def test_the_table_picture_places_each_cell_by_its_index_and_draws_blocked_and_silent_cells(room, tmp_path):
    _, spec = room
    nx, ny = spec.grid.nx, spec.grid.ny
    gain = np.linspace(-90, -40, nx * ny).reshape(ny, nx)
    gain[0, 3] = np.nan  # a free cell no path reaches
    blocked = np.zeros((ny, nx), bool)
    blocked[1, 1] = True
    (grid,) = gain_grids(_table(nx, ny, gain), nx, ny, 1)
    np.testing.assert_array_equal(grid, gain)
    png = render_cells_png(spec, _table(nx, ny, gain), blocked, tmp_path / "cells.png")
    assert _colour_share(png, BLOCKED_COLOUR) > 0.002, "the blocked cell is drawn"
    only_free = render_cells_png(spec, _table(nx, ny, gain), np.zeros_like(blocked), tmp_path / "free.png")
    assert _colour_share(only_free, BLOCKED_COLOUR) < _colour_share(png, BLOCKED_COLOUR)
    assert _colour_share(png, NO_PATH_COLOUR) > 0  # (the figure's margins are white too: drawn, not measured)


@pytest.mark.sionna
def test_a_build_stores_and_prints_both_pictures(root, room, capsys):
    from dtradar_data.pipeline.builder import build
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    path, _ = room
    config = BuildConfig(
        scene=str(path),
        variant="blueprint",
        rt=RTSettings(max_depth=1, samples_per_src=2_000, device="cpu"),
        coverage_samples=20_000,
        progress=False,
    )
    (ds,) = build(config)
    out = capsys.readouterr().out
    for picture in ("coverage.png", "cells.png"):
        assert (ds.path / picture).stat().st_size > 1000
        assert f"picture-room/blueprint: picture {ds.path / picture}" in out
    assert "cells.png" in json.loads((ds.path / "meta.json").read_text())["files"]
    (again,) = build(config)  # reused: it says where the stored pictures are
    assert again.version == ds.version and f"picture {ds.path / 'cells.png'}" in capsys.readouterr().out
    (plain,) = build(replace(config, coverage_map=False, rt=replace(config.rt, seed=7)))
    assert (plain.path / "cells.png").is_file() and not (plain.path / "coverage.png").exists()
