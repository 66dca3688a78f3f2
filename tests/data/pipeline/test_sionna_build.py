"""A bundled Sionna scene traced end to end with the real ray tracer: a handful of street-canyon cells, few rays."""

import pytest

pytestmark = pytest.mark.sionna


def test_a_bundled_sionna_scene_builds_a_small_grid_and_loads_by_its_dataset_name(root):
    import dtradar_data
    from dtradar_data.pipeline.builder import build
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    cfg = BuildConfig(
        scene="sionna:simple_street_canyon",
        grid=(-30.0, -20.0, 5.0, 6, 9),
        tx=(0.0, 0.0, 20.0),
        coverage_samples=20_000,
        progress=False,
        rt=RTSettings(max_depth=1, samples_per_src=1_000, device="cpu"),
    )
    (ds,) = build(cfg)
    loaded = dtradar_data.load("sionna-simple_street_canyon/blueprint")
    assert loaded.version == ds.version and (ds.grid_info.nx, ds.grid_info.ny) == (6, 9)
    assert 0 < ds.blocked.sum() < ds.blocked.size
    free = ds.frame.filter(~ds.frame["blocked"])
    assert (free["num_paths"] > 0).all()  # a street under its transmitter: every free cell sees it
    assert ds.meta["scene_spec"]["base"]["xml"] == "sionna:simple_street_canyon"
    assert (ds.path / "coverage.png").stat().st_size > 10_000
