"""A tiny city quadrant traced end to end with the real ray tracer: Dallas Q3 at 20 m cells, few rays."""

import pytest

pytestmark = pytest.mark.sionna


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_dallas_quadrant_builds_and_loads_by_name_with_its_city_card_and_overview(root):
    import dtradar_data
    from dtradar_data.pipeline.builder import build
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings

    cfg = BuildConfig(
        scene="dallas-q3",
        variant="blueprint",
        cell_m=20.0,
        coverage_samples=50_000,
        progress=False,
        rt=RTSettings(max_depth=1, samples_per_src=1_000, device="cpu"),
    )
    (ds,) = build(cfg)
    loaded = dtradar_data.load("dallas-q3/blueprint")
    assert loaded.version == ds.version and ds.grid_info.nx == 10 and ds.grid_info.ny == 13
    assert 0 < ds.blocked.sum() < ds.blocked.size
    free = ~ds.blocked
    assert (ds.frame.filter(~ds.frame["blocked"])["num_paths"] > 0).mean() > 0.2  # 1000 rays, one bounce
    assert free.sum() == ds.frame.filter(~ds.frame["blocked"]).height
    card = (ds.path / "README.md").read_text()
    assert "license: odbl" in card and "Quadrant Q3 of dallas" in card and "city.png" in card
    assert (ds.path / "city.png").stat().st_size > 10_000
    assert ds.meta["city"]["tx"]["paper_m"] == [205.0, 159.0, 18.0]
    # the city's [rt] buffer replaces the indoor default; the samples the test asked for are kept
    assert ds.meta["rt"]["max_num_paths_per_src"] == 10_000_000 and ds.meta["rt"]["samples_per_src"] == 1_000
