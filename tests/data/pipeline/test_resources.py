"""A build that cannot fit in memory or on disk fails before anything is traced, saying what to lower."""

import pytest

from dtradar_data.pipeline import builder, resources, tracing
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.resources import InsufficientResourcesError, estimate_memory
from dtradar_data.rt.settings import RTSettings


@pytest.fixture
def no_tracing(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("traced although the build could not fit")

    monkeypatch.setattr(tracing, "trace_grid", refuse)


def test_too_little_memory_fails_before_tracing_naming_the_path_buffer(root, monkeypatch, no_tracing):
    monkeypatch.setattr(resources, "available_memory", lambda: 512 * 2**20)
    with pytest.raises(InsufficientResourcesError, match="max-num-paths-per-src") as err:
        builder.build(BuildConfig(scene="cubicle", variant="all"))
    assert "0.5 GiB are available" in str(err.value)
    assert not (root / "datasets").exists()


def test_too_little_disk_fails_before_tracing(root, monkeypatch, no_tracing):
    monkeypatch.setattr(resources.shutil, "disk_usage", lambda p: type("U", (), {"free": 1_000})())
    with pytest.raises(InsufficientResourcesError, match="MiB of disk"):
        builder.build(BuildConfig(scene="dallas-q3", variant="blueprint"))


def test_a_city_quadrant_needs_the_larger_outdoor_path_buffer_in_the_estimate():
    assert estimate_memory(RTSettings(max_num_paths_per_src=10_000_000)) > 2 * 2**30
    assert estimate_memory(RTSettings()) < 1 * 2**30
