"""Shared fixtures: every test that touches the store gets its own empty data root."""

import os
import sys

import pytest


@pytest.fixture()
def root(tmp_path, monkeypatch):
    """An empty data root (``DTRADAR_DATA_ROOT``) under the test's temporary folder."""
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "root"))
    return tmp_path / "root"


#: A user's 2 m x 1.5 m room file with one box: the smallest scene the tracer builds in seconds.
TINY_ROOM = """
format = 1
[scene]
name = "tiny-room"
title = "Tiny room"
description = "A user's own 2 m x 1.5 m room with one box"
source = "test"
licence = "CC0-1.0"
attribution = "nobody"
[room]
width_m = 2.0
length_m = 1.5
height_m = 2.5
wall_thickness_m = 0.2
wall_material = "brick"
floor_material = "concrete"
floor_thickness_m = 0.1
ceiling_material = "concrete"
ceiling_thickness_m = 0.1
[grid]
cell_m = 0.5
nx = 4
ny = 3
[tx]
position_m = [1.0, 0.75, 2.4]
[robot]
rx_height_m = 1.0
robot_height_m = 1.0
[[objects]]
name = "box_01"
kind = "box"
material = "wood"
x_m = 0.25
y_m = 0.25
width_m = 0.4
length_m = 0.4
height_m = 0.8
"""


@pytest.fixture()
def tiny_room() -> str:
    """The text of a tiny user's room file (``TINY_ROOM``), for tests that read or trace a scene file."""
    return TINY_ROOM


def pytest_sessionfinish(session, exitstatus):
    session.config._dtradar_exitstatus = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """End the process once pytest has reported. The native libraries the tests load (Dr.Jit's LLVM backend, torch's
    thread pools, Ray's client) have crashed the interpreter while it tore them down after the last test: a
    segmentation fault in 2 of 6 full runs on this machine, every test passed, no Python frame in the crash.
    Nothing of the tests' results is left to write at this point."""
    status = getattr(config, "_dtradar_exitstatus", None)
    if status is None:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
