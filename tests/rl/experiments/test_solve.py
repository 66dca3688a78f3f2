"""``python -m dtradar_rl solve``: V*/Q* for every target written into the data root, the greedy policy's success
and SPL on the evaluation pairs (1.000 under the geodesic reward), a picture, and a second run that reuses the
stored solution. A tiny synthetic twin."""

import json

from dtradar_rl.cli import main


def test_solve_writes_the_solution_and_the_greedy_policy_walks_shortest_paths(root, tmp_path, capsys):
    out = tmp_path / "solve"
    args = ["solve", "--scene", "synthetic-12x8", "--variants", "blueprint", "--pairs", "50", "--out", str(out)]
    assert main(args) == 0
    result = json.loads((out / "solve.json").read_text())
    rows = {r["reward"]: r for r in result["rows"]}
    assert set(rows) == {"geodesic", "paper"}
    geo = rows["geodesic"]
    assert geo["success_rate"] == 1.0 and geo["spl"] == 1.0 and not geo["cached"]
    assert (out / "value_blueprint_geodesic.png").stat().st_size > 1000
    folder = root / "tabular" / "synthetic-12x8" / "blueprint"
    assert any(p.name == "solution.json" for p in folder.rglob("*"))
    assert main(args) == 0
    again = json.loads((out / "solve.json").read_text())
    assert all(r["cached"] for r in again["rows"])
    assert "| synthetic-12x8/blueprint | geodesic |" in capsys.readouterr().out


def test_solve_refuses_a_bad_discount_with_exit_status_2(root, capsys):
    assert main(["solve", "--scene", "synthetic-12x8", "--gamma", "1.5"]) == 2
    assert "discount" in capsys.readouterr().err


def test_a_scene_without_a_dynamic_twin_solves_its_blueprint_and_says_so(root, tmp_path, capsys, monkeypatch):
    from dtradar_data.core.errors import DatasetNotFoundError
    from dtradar_rl.experiments import solve

    real = solve.load_dataset

    def no_dynamic(name):
        if name.endswith("/dynamic"):
            raise DatasetNotFoundError(f"{name} has not been built", hint="make dataset")
        return real(name)

    monkeypatch.setattr(solve, "load_dataset", no_dynamic)
    out = tmp_path / "solve"
    assert (
        main(["solve", "--scene", "synthetic-12x8", "--rewards", "geodesic", "--pairs", "20", "--out", str(out)]) == 0
    )
    rows = json.loads((out / "solve.json").read_text())["rows"]
    assert [r["dataset"] for r in rows] == ["synthetic-12x8/blueprint"]
    assert "synthetic-12x8/dynamic is not solved" in capsys.readouterr().out
