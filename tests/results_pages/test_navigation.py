"""The navigation pages' tables (navigation.md, navigation-movers.md): from JSONs holding the pages' numbers, in the
shape of what their commands write (``python -m dtradar_rl eval``'s results.json, one per run; bench_nav.py's,
bench_latency.py's, bench_dynamic.py's and bench_rl.py's JSON), each renderer gives the committed block back byte for
byte, and a re-run's number lands in it."""

import json
import math
import re

import pytest

PAGE, MOVERS = "navigation.md", "navigation-movers.md"


def renders_the_page(pages, tmp_path, marker: str, runs: dict[str, dict], change: tuple[str, str, str, str],
                     page: str = PAGE) -> None:  # fmt: skip
    """``runs`` (the JSON of each path of the block's marker) give the page's block unchanged; ``change`` = (a path,
    a number in its JSON, what a re-run measured instead, how the table shows that) lands in the block."""
    rp = pages.results_pages
    text, block = pages.block_of(page, marker)
    assert list(runs) == list(dict.fromkeys(rp.paths(block)))  # every run of the marker, in its order
    for path, data in runs.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(json.dumps(data), encoding="utf-8")
    was = text[block.start : block.end]
    assert rp.render(block, tmp_path) == was
    path, old, new, shown = change
    assert old in json.dumps(runs[path])
    (tmp_path / path).write_text(json.dumps(runs[path]).replace(old, new, 1), encoding="utf-8")
    now = rp.render(block, tmp_path)
    assert now.split("\n")[1:3] == was.split("\n")[1:3]  # the page's header and separator
    assert shown in now and shown not in was


def rows_of(pages, marker: str) -> list[list[str]]:
    text, block = pages.block_of(PAGE, marker)
    return pages.rows_of(text, block)


def paths_of(pages, marker: str) -> list[str]:
    return pages.results_pages.paths(pages.block_of(PAGE, marker)[1])


def plain(cell: str) -> str:
    return cell.replace("**", "").replace("`", "")


def numbers(cell: str) -> list[float]:
    """``1.000 / 0.987 / 0.01`` -> its numbers."""
    return [float(x) for x in plain(cell).split(" / ")]


def result(twin: str, variant: str, cell: str, *, shield: bool = False, case: str = "") -> dict:
    """An eval row of ``twin/variant`` holding a ``success / SPL [/ collisions]`` cell."""
    values = numbers(cell) + [0.0]
    return {
        "case": case or f"{twin}/blueprint -> {twin}/{variant}" + " (shielded)" * shield,
        "dataset": f"{twin}/{variant}",
        "shield": shield,
        "success_rate": values[0],
        "spl": values[1],
        "collisions": values[2],
    }


def eval_run(path: str, twin: str, results: list[dict], *, noise: str = "none", **train) -> dict:
    """What ``python -m dtradar_rl eval --out <folder of path>`` writes: its config and rows."""
    wall_s, free = train.pop("wall_s", None), train.pop("free", None)
    return {
        "config": {
            "eval": {"scene": twin, "noise": noise, "out": path.removesuffix("/results.json"), "seed": 2024},
            "checkpoint": "runs/x/model.pt",
            "train": {"preset": "memory-escape-noise-margin", "total_env_steps": 600_000, "seed": 0, **train},
            "train_stats": {} if wall_s is None else {"wall_s": wall_s, "env_steps": 600_064},
            "free_cells": {} if free is None else {f"{twin}/blueprint": free},
        },
        "results": [*results, result(twin, "blueprint", "0.5 / 0.5", case=f"planner: {twin}/blueprint")],
    }


NAMES = {"Dallas Q1": "dallas-q1", "Dallas Q2": "dallas-q2", "Dallas Q3": "dallas-q3", "Dallas Q4": "dallas-q4",
         "Munich, ten transmitters": "sionna-munich-10tx"}  # fmt: skip


def test_the_margin_table_is_one_eval_run_per_row_with_the_default_agent_at_its_budget_in_bold(pages, tmp_path):
    from dtradar_rl.train.config import budget_for

    runs = {}
    for path, (twin, agent, steps, bp, dyn, wall) in zip(
        paths_of(pages, "navigation-margin"), rows_of(pages, "navigation-margin"), strict=True
    ):
        name, free = twin.rsplit(" (", 1)
        free = int(free.rstrip(")").replace(" ", ""))
        number, unit = steps.split()
        steps = budget_for(free) if agent.startswith("**") else round(float(number) * (1e6 if unit == "M" else 1e3))
        scene = NAMES.get(name, name)
        res = [result(scene, "blueprint", bp)] + ([] if dyn == "-" else [result(scene, "dynamic", dyn)])
        res.append(result(scene, "blueprint", "0.1 / 0.1", shield=True))  # eval's shielded row: not this table's
        wall_s = float(wall.replace(" ", "")) + 0.2
        runs[path] = eval_run(path, scene, res, preset=plain(agent), total_env_steps=steps, wall_s=wall_s, free=free)
    last = list(runs)[-1]
    renders_the_page(pages, tmp_path, "navigation-margin", runs, (last, "739.2", "701.0", "| 701 |"))


def test_the_exact_or_noisy_features_table_pairs_two_presets_eval_runs_per_twin_and_noise(pages, tmp_path):
    runs = {}
    paths = iter(paths_of(pages, "navigation-noise-trained"))
    for twin, noise, bp, dyn, other in rows_of(pages, "navigation-noise-trained"):
        ours = [result(twin, "blueprint", bp)] + ([] if dyn == "-" else [result(twin, "dynamic", dyn)])
        theirs = [result(twin, v, cell) for v, cell in zip(("blueprint", "dynamic"), other.split(" · "), strict=False)]
        for preset, res in (("memory-escape-noise", ours), ("memory-escape", theirs)):
            path = next(paths)
            runs[path] = eval_run(path, twin, res, noise=noise, preset=preset)
    first = list(runs)[1]  # memory-escape on the cubicle without noise
    renders_the_page(pages, tmp_path, "navigation-noise-trained", runs, (first, "0.98", "0.984", "0.984"))


def test_sb3s_table_is_bench_navs_sb3_rows_without_noise(pages, tmp_path):
    rows = []
    for twin, bp, dyn in rows_of(pages, "navigation-sb3"):
        for variant, cell in (("blueprint", bp), ("dynamic", dyn)):
            if cell != "-":
                for agent, noise in (("SB3 DQN", "none"), ("SB3 DQN", "realistic"), ("memory-escape", "none")):
                    values = numbers(cell) + [0.0] if (agent, noise) == ("SB3 DQN", "none") else [0.5, 0.5, 0.5]
                    rows.append({"scene": twin, "seed": 0, "agent": agent, "noise": noise, "twin": variant,
                                 "success": values[0], "spl": values[1], "collisions": values[2],
                                 "p50_ms": 0.1, "p99_ms": 0.2, "train_s": 300.0})  # fmt: skip
    data = {"args": {"pairs": 500, "seeds": [0], "steps": 0, "sb3_seconds": 300.0}, "rows": rows, "goals": {}}
    renders_the_page(pages, tmp_path, "navigation-sb3", {"results/bench_nav_v0.json": data},
                     ("results/bench_nav_v0.json", "26.13", "25.5", "25.50"))  # fmt: skip


def test_the_decision_times_are_bench_latencys_runs_on_each_twin_every_case_they_hold(pages, tmp_path):
    runs = {}
    paths = paths_of(pages, "navigation-latency")
    for path in paths:
        runs[path] = {"scene": path.split("bench_latency_")[1].removesuffix(".json"), "decisions": 1000, "rows": [],
                      "machine": {"start": {}, "end": {}}}  # fmt: skip
    for twin, policy, threads, load, p50, p99 in rows_of(pages, "navigation-latency"):
        (data,) = [d for d in runs.values() if d["scene"] == twin]
        for run, (a, b) in enumerate(zip(p50.split(), p99.split(), strict=True)):
            data["rows"].append({"policy": policy, "threads": int(threads), "load": load, "run": run,
                                 "p50_ms": float(a), "p99_ms": float(b)})  # fmt: skip
    renders_the_page(pages, tmp_path, "navigation-latency", runs, (paths[1], "1.625", "1.7", "1.700"))


def test_the_unseen_obstacles_table_is_one_eval_run_per_scene_and_preset(pages, tmp_path):
    runs = {}
    for path, (scene, preset, wall, bp, dyn, shielded) in zip(
        paths_of(pages, "navigation-unseen"), rows_of(pages, "navigation-unseen"), strict=True
    ):
        res = [result(scene, "blueprint", bp), result(scene, "dynamic", dyn)]
        res += [result(scene, "blueprint", "0.5 / 0.5", shield=True), result(scene, "dynamic", shielded, shield=True)]
        runs[path] = eval_run(path, scene, res, preset=preset, total_env_steps=600_000, wall_s=float(wall[:-2]))
    first = list(runs)[0]
    renders_the_page(pages, tmp_path, "navigation-unseen", runs, (first, "38.9", "40.2", "/ 40.2 |"))


def test_the_noise_levels_table_is_one_eval_run_per_noise(pages, tmp_path):
    runs = {}
    for path, (noise, bp, dyn, shielded) in zip(
        paths_of(pages, "navigation-noise-levels"), rows_of(pages, "navigation-noise-levels"), strict=True
    ):
        res = [result("cubicle", "blueprint", bp), result("cubicle", "dynamic", dyn)]
        res.append(result("cubicle", "dynamic", shielded, shield=True))
        runs[path] = eval_run(path, "cubicle", res, noise=noise, preset="tuned")
    renders_the_page(pages, tmp_path, "navigation-noise-levels", runs, (list(runs)[2], "15.02", "14.3", "14.30"))


def seeds(cell: str, n: int = 3) -> list[float]:
    """``mean ± std`` (or one value) as ``n`` seeds' values with that mean and standard deviation."""
    mean, _, std = plain(cell).partition(" ± ")
    d = float(std or 0) * math.sqrt(n / (n - 1)) if n > 1 else 0.0
    return [float(mean) - d, float(mean), float(mean) + d][:n] if n == 3 else [float(mean)] * n


def test_the_zero_shot_table_joins_bench_dynamics_runs_and_make_bench_rls(pages, tmp_path):
    paths = paths_of(pages, "navigation-zero-shot")
    dyn = {p: {"args": {"scenes": [], "presets": ["memory"], "seeds": [0, 1, 2], "steps": 600_000, "pairs": 500},
               "rows": [], "adapt": []} for p in paths if "bench_dynamic" in p}  # fmt: skip
    rl = {p: {"dataset": {"name": ""}, "train": {}, "train_robust": {"config": {"seed": 0}}, "eval": []}
          for p in paths if "bench_rl" in p}  # fmt: skip
    dyn["results/bench_dynamic_long.json"]["args"] |= {"scenes": ["cubicle", "meeting"], "steps": 1_200_000}
    for scene, agent, bp, dy, collisions, decision in rows_of(pages, "navigation-zero-shot"):
        if agent.startswith(("robust", "SB3")):
            data = rl["results/bench_rl.json" if scene == "cubicle" else f"results/bench_rl_{scene}.json"]
            data["dataset"]["name"] = f"{scene}/blueprint"
            label = "ours (robust, 10 extra obstacles): " if agent.startswith("robust") else "SB3 DQN: "
            for variant, cell in (("blueprint", bp), ("dynamic", f"{dy} / {collisions}"), ("dynamic", "0.1 / 0.1")):
                shielded = " (shielded)" * (cell == "0.1 / 0.1")
                case = f"{label}{scene}/blueprint -> {scene}/{variant}{shielded}"
                data["eval"].append(result(scene, variant, cell, case=case))
            continue
        data = dyn["results/bench_dynamic_long.json" if "1.2 M" in agent else f"results/bench_dynamic_{scene}.json"]
        if scene not in data["args"]["scenes"]:
            data["args"]["scenes"].append(scene)
        n = 1 if agent.startswith("planner") else 3
        for variant, cell, coll in (("blueprint", bp, "0.0"), ("dynamic", dy, collisions)):
            s, spl = (seeds(c, n) for c in plain(cell).split(" / "))
            for k in range(n):
                data["rows"].append({"scene": scene, "agent": "planner" if n == 1 else "memory",
                                     "seed": None if n == 1 else k, "twin": variant, "success_rate": s[k],
                                     "spl": spl[k], "collisions": seeds(coll, n)[k],
                                     "latency_ms": float(decision)})  # fmt: skip
    runs = {p: dyn.get(p) or rl[p] for p in paths}
    renders_the_page(pages, tmp_path, "navigation-zero-shot", runs,
                     ("results/bench_rl_meeting.json", "19.8", "18.4", "| 18.4 |"))  # fmt: skip


def curve(points: list[tuple[float, float]], spl: float = 0.0) -> list[dict]:
    return [{"train_s": t, "env_steps": 0, "success_rate": s, "spl": spl, "collisions": 0.0} for t, s in points]


def test_the_twin_update_is_bench_dynamics_adapt_rows(pages, tmp_path):
    adapt = []
    for scene, seed, zero, ft, plain_ft, scratch in rows_of(pages, "navigation-adapt"):
        first, end = plain(ft).split(" / ")
        end, spl = end.rstrip(")").split(" (")
        p_first, p_end = plain_ft.split(" / ")

        def points(first: str, end: str, zero: str = zero) -> list[tuple[float, float]]:
            t = None if first == "never" else float(first.rstrip(" s"))
            return [(0.0, float(zero))] + ([] if t is None else [(t, 0.99)]) + [(max(t or 0, 20.0), float(end))]

        curves = {"finetune": curve(points(first, end), float(spl)), "finetune-dqn": curve(points(p_first, p_end)),
                  "scratch": curve([(0.0, 0.2), (20.0, float(scratch))])}  # fmt: skip
        adapt.append({"scene": scene, "seed": int(seed), "curves": curves, "machine": "", "wall_s": 70.0})
    data = {"args": {"scenes": ["cubicle", "meeting"], "seconds": 20.0, "name": "bench_dynamic_adapt"},
            "rows": [], "adapt": adapt}  # fmt: skip
    renders_the_page(pages, tmp_path, "navigation-adapt", {"results/bench_dynamic_adapt.json": data},
                     ("results/bench_dynamic_adapt.json", "16.1", "12.3", "**12.3 s**"))  # fmt: skip


# -- among movers: eval runs on the moving twins, the rows' labels given by the marker ------------------------------
def moving(twin: str, cells: list[str], n: int, *, shield: bool = False, planner: bool = False) -> list[dict]:
    """``n`` seeds' eval rows on ``twin`` (``<scene>/moving``) holding the cells success, SPL, mover collisions and
    hits."""
    scene = twin.split("/")[0]
    values = [seeds(c, n) for c in cells]
    case = ("planner: " if planner else "") + f"{scene}/blueprint -> {twin}" + " (shielded)" * shield
    return [
        {"case": case, "dataset": twin, "shield": shield, "success_rate": values[0][k], "spl": values[1][k],
         "collisions": 0.0, "mover_collisions": values[2][k], "mover_hits": values[3][k]}
        for k in range(n)
    ]  # fmt: skip


SEED = re.compile(r"-s\d+/results\.json$")


def same_run(a: str, b: str) -> bool:
    """Two seeds of one run: folders that differ only by a last ``-s<seed>``."""
    return bool(SEED.search(b)) and SEED.sub("", a) == SEED.sub("", b)


def movers_runs(pages, marker: str, numbers_at: slice, budget_at: int | None = None) -> dict[str, dict]:
    """The marker's runs holding its table's rows: a label opens the next run (its seeds: the paths that differ by a
    last ``-s<seed>``), a shielded label is the run's shielded row, a planner label its planner row."""
    text, block = pages.block_of(MOVERS, marker)
    paths = pages.results_pages.paths(block)
    runs: dict[str, dict] = {}
    at, group = 0, []
    for row in pages.rows_of(text, block):
        twin, label, cells = row[0], row[1], [plain(c) for c in row[numbers_at]]
        if "shielded" in label:  # the run before's shielded row
            for k, path in enumerate(group):
                runs[path]["results"].append(moving(twin, cells, len(group), shield=True)[k])
            continue
        group = [paths[at]]
        while SEED.search(paths[at]) and at + len(group) < len(paths) and same_run(paths[at], paths[at + len(group)]):
            group.append(paths[at + len(group)])
        at += len(group)
        n = len(group)
        planner = label.startswith("planner")
        wall = row[-1].rstrip(" s") if budget_at is not None or row[-1].endswith(" s") else ""
        train = {"total_env_steps": 1_200_000}
        if budget_at is not None:
            number, unit = row[budget_at].split()
            train["total_env_steps"] = round(float(number) * (1e6 if unit == "M" else 1e3))
        for k, path in enumerate(group):
            res = moving(twin, cells, n)[k : k + 1]
            if planner:  # the planner's row, and its checkpoint's
                res = moving(twin, cells, 1, planner=True) + moving(twin, ["0.5", "0.5", "0.5", "0.5"], 1)
            runs[path] = eval_run(path, twin.split("/")[0], res, seed=k, wall_s=float(wall) + 0.3 if wall else None,
                                  **train)  # fmt: skip
    assert at == len(paths)
    return runs


def test_the_agents_trained_among_movers_are_eval_runs_with_the_fewest_mover_collisions_in_bold(pages, tmp_path):
    marker = "navigation-movers-trained"
    runs = movers_runs(pages, marker, slice(3, 7), budget_at=2)
    renders_the_page(pages, tmp_path, marker, runs, (list(runs)[5], "0.002", "0.001", "**0.001**"), MOVERS)


def test_the_flags_table_shows_a_run_of_several_seeds_as_their_mean(pages, tmp_path):
    runs = movers_runs(pages, "navigation-movers-flags", slice(2, 6))
    renders_the_page(
        pages, tmp_path, "navigation-movers-flags", runs, (list(runs)[0], "138.3", "141.0", "141 s"), MOVERS
    )


def test_the_sensing_radius_table_gives_each_runs_seeds_mean_and_spread_and_the_planners_row(pages, tmp_path):
    marker = "navigation-movers results/navigation/movers/cubicle-zero-shot-s0"
    runs = movers_runs(pages, marker, slice(2, 6))
    planner = "results/navigation/movers/dallas-q3-planner/results.json"
    renders_the_page(pages, tmp_path, marker, runs, (planner, "0.786", "0.79", "| 0.790 |"), MOVERS)


def test_the_planner_among_movers_is_its_row_of_an_eval_run_on_each_twin(pages, tmp_path):
    marker = "navigation-movers results/navigation/movers/cubicle-planner"
    runs = movers_runs(pages, marker, slice(2, 6))
    renders_the_page(pages, tmp_path, marker, runs, (list(runs)[1], "0.25", "0.27", "| 0.27 |"), MOVERS)


@pytest.mark.slow  # builds an agent and evaluates it (5 s): make test-all runs it
def test_eval_records_each_static_twins_free_cells_for_the_margin_tables_twin_column(tmp_path, monkeypatch):
    from dtradar_rl.cli import main
    from dtradar_rl.task.twins import load_dataset

    monkeypatch.chdir(tmp_path)
    assert main(["agent", "--scene", "synthetic-6x5"]) == 0
    assert main(["eval", "--scene", "synthetic-6x5", "--pairs", "4", "--no-planner", "--plot-paths", "0"]) == 0
    config = json.loads((tmp_path / "runs/synthetic-6x5/eval/results.json").read_text())["config"]
    blueprint = load_dataset("synthetic-6x5/blueprint")
    assert config["free_cells"]["synthetic-6x5/blueprint"] == int((~blueprint.blocked).sum()) > 0
