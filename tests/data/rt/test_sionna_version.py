"""The patched path solver copies Sionna internals of one release: a tracer refuses any other sionna-rt with a typed
error naming both versions and the fix, before it loads a scene or traces (no ray tracer needed)."""

from pathlib import Path

import pytest
import tomllib

from dtradar_data.core.errors import RayTracerUnavailableError
from dtradar_data.rt import sionna_version
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.sionna_version import PATCHED_SIONNA_RT_VERSIONS, check_patched_sionna_rt

PYPROJECT = Path(__file__).resolve().parents[3] / "pyproject.toml"


def test_the_pinned_sionna_rt_is_a_release_the_patch_is_written_for():
    deps = tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]["dependencies"]
    pin = next(d for d in deps if d.startswith("sionna-rt=="))
    assert pin.removeprefix("sionna-rt==") == PATCHED_SIONNA_RT_VERSIONS[-1]


def test_the_installed_sionna_rt_passes():
    if sionna_version.installed_sionna_rt() is None:
        pytest.skip("sionna-rt is not installed")
    check_patched_sionna_rt()


def test_another_sionna_rt_is_refused_naming_both_versions_and_the_fix(monkeypatch):
    monkeypatch.setattr(sionna_version, "installed_sionna_rt", lambda: "2.3.0")
    with pytest.raises(RayTracerUnavailableError) as caught:
        check_patched_sionna_rt()
    assert "sionna-rt 2.3.0 is installed" in caught.value.message
    assert f"sionna-rt {PATCHED_SIONNA_RT_VERSIONS[0]}" in caught.value.message
    assert f"pip install sionna-rt=={PATCHED_SIONNA_RT_VERSIONS[-1]}" in caught.value.hint
    assert "--rt.no-batch-independent" in caught.value.hint


def test_a_missing_sionna_rt_is_left_to_the_import_to_report(monkeypatch):
    monkeypatch.setattr(sionna_version, "installed_sionna_rt", lambda: None)
    check_patched_sionna_rt()


def test_the_tracer_checks_the_version_before_it_loads_anything(monkeypatch):
    from dtradar_data.rt.tracer import RayTracer

    monkeypatch.setattr(sionna_version, "installed_sionna_rt", lambda: "2.3.0")
    with pytest.raises(RayTracerUnavailableError, match="sionna-rt 2.3.0"):
        RayTracer(None, RTSettings(batch_independent=True))  # no scene at all: the check comes first
