"""Shared fixtures: every test that touches the store gets its own empty data root."""

import pytest


@pytest.fixture()
def root(tmp_path, monkeypatch):
    """An empty data root (``DTRADAR_DATA_ROOT``) under the test's temporary folder."""
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "root"))
    return tmp_path / "root"
