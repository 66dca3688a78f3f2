"""Importing d3rlpy or Stable-Baselines3 prints nothing: the legacy ``gym`` package they bring in (0.26.2, through
d3rlpy) prints whatever notice ``gym-notices`` holds for its version, and the install pins a ``gym-notices`` that holds
none for it (pyproject.toml; why: docs/dependencies.md)."""

import subprocess
import sys
from importlib import metadata

import pytest

BANNER = "Gym has been unmaintained"
FIX = "the gym notice is back: run make setup (pyproject.toml pins gym-notices==0.0.8, docs/dependencies.md)"


def test_the_installed_gym_notices_hold_no_notice_for_the_installed_gym():
    pytest.importorskip("gym_notices")
    from gym_notices.notices import notices

    assert metadata.version("gym") not in notices, FIX


@pytest.mark.parametrize(
    "module",
    [
        "d3rlpy",
        "stable_baselines3",
        "gym",
        # our entry to d3rlpy, used as the offline jobs use it
        "dtradar_rl.offline.formats as f; f.import_d3rlpy()",
    ],
)
@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_an_import_that_brings_in_gym_prints_nothing(module):
    pytest.importorskip(module.split()[0].split(".")[0])
    out = subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert BANNER not in out.stdout + out.stderr, FIX
    assert (out.stdout, out.stderr) == ("", "")
