"""Fixtures shared by the experiment tests."""

import json

import pytest

from dtradar_rl.cli import main

#: The twin the solve-cache tests solve (small: a solve takes a fraction of a second).
SOLVE_SCENE = "synthetic-12x8"


@pytest.fixture()
def solve():
    """``solve(tmp_path, capsys)``: one solve of the blueprint under the geodesic reward, its results outside the data
    root, as ``(its row of solve.json, stderr)``."""

    def run(tmp_path, capsys) -> tuple[dict, str]:
        out = tmp_path / "solve"
        args = ["solve", "--scene", SOLVE_SCENE, "--variants", "blueprint", "--rewards", "geodesic", "--pairs", "30"]
        assert main([*args, "--out", str(out)]) == 0
        (row,) = json.loads((out / "solve.json").read_text())["rows"]
        return row, capsys.readouterr().err

    return run
