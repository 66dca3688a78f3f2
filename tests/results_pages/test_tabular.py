"""The tables of the tabular page: each renderer gives the committed page's block back from JSONs in the shape of
``make solve``'s solve.json, ``make bench-tabular``'s JSON and the offline benchmark's bench.json holding the page's
numbers (read off the committed table), and a re-run's number lands in it."""

PAGE = "tabular.md"


def renders_several(pages, tmp_path, capsys, marker: str, datas: list, change: tuple[int, str, str]) -> None:
    pages.renders_runs(tmp_path, capsys, PAGE, marker, datas, change)


def two(cell: str) -> list[float | None]:
    """``98.8 / 83.6`` -> [98.8, 83.6]; ``-`` -> None."""
    return [None if x.strip() == "-" else float(x) for x in cell.split("/")]


def test_the_exact_solutions_table_sets_every_scenes_solve_json_side_by_side(pages, tmp_path, capsys):
    text, block = pages.block_of(PAGE, "tabular-solve")
    results: dict[str, dict] = {}
    for twin, size, geo_s, paper_s, geo, paper in pages.rows_of(text, block):
        cells, targets = (int(x.replace(" ", "")) for x in size.split("×"))
        scene = twin.split("/")[0]
        result = results.setdefault(scene, {"config": {"scene": scene, "rewards": ["geodesic", "paper"], "gamma": 0.9},
                                            "rows": []})  # fmt: skip
        for reward, seconds, greedy in (("geodesic", geo_s, geo), ("paper", paper_s, paper)):
            success, spl = two(greedy)
            result["rows"].append({"dataset": twin, "reward": reward, "cells": cells, "targets": targets, "sweeps": 9,
                                   "solve_s": pages.num(seconds), "cached": False, "success_rate": success,
                                   "spl": spl})  # fmt: skip
    datas = [results[p.split("/")[2]] for p in pages.results_pages.paths(block)]
    assert len(datas) == 8
    renders_several(pages, tmp_path, capsys, "tabular-solve", datas, (7, "36.8", "37.9"))


def test_solve_times_keep_two_decimals_under_ten_seconds_and_one_under_a_hundred():
    from dtradar_rl.experiments.solve import _seconds

    seconds = (0.4213, 0.0084, 1.0, 8.304, 20.24, 136.6, 0.5)
    assert [_seconds(x) for x in seconds] == ["0.42", "0.01", "1.0", "8.3", "20.2", "137", "0.5"]


KEYS = {"Q-learning": "qlearning", "Dyna-Q": "dyna", "DQN (memory-escape-noise)": "dqn", "DQN (tuned)": "tuned"}
SCENES = {"cubicle": "cubicle", "Dallas Q3": "dallas-q3"}
REACH = {"never": None, "10 K": 10_240, "41 K": 40_960, "120 K": 120_064, "180 K": 180_224, "300 K": 300_032,
         "420 K": 420_096}  # fmt: skip


def bench_tabular(pages) -> dict:
    """bench_tabular.json holding both tables' numbers (and curve points the page leaves out)."""
    text, curves = pages.block_of(PAGE, "tabular-curves")
    _, learners = pages.block_of(PAGE, "tabular-learners")
    scenes = {s: {"datasets": {}, "ambiguity": {}, "learners": {}} for s in SCENES.values()}
    for twin, label, train_s, reach, dynamic, oracle in pages.rows_of(text, learners):
        success, spl, collisions = two(dynamic)
        final = {"blueprint/-": {"success": 1.0, "spl": 1.0, "collisions": 0.0}}
        if label.startswith("DQN"):
            final["dynamic/-"] = {"success": success, "spl": spl, "collisions": collisions}
        else:
            final["dynamic/fingerprint"] = {"success": success, "spl": spl, "collisions": collisions}
            final["dynamic/oracle"] = dict(zip(("success", "spl"), two(oracle), strict=True)) | {"collisions": 1.0}
        scenes[SCENES[twin]]["learners"][KEYS[label]] = {
            "label": label, "curve": [], "train_s": float(train_s), "final": final,
            "reach": dict(zip(("0.9", "0.99"), (REACH[r.strip()] for r in reach.split("/")), strict=True)),
        }  # fmt: skip
    for cells in pages.rows_of(text, curves):
        steps = int(cells[0].replace(",", ""))
        for i, cell in enumerate(cells[1:]):
            scene = list(scenes.values())[i // 4]
            learner = list(scene["learners"].values())[i % 4]
            success, spl = two(cell)
            learner["curve"].append({"env_steps": steps, "success": success, "spl": spl, "collisions": 0.0})
    for scene in scenes.values():  # checkpoints the page leaves out
        for learner in scene["learners"].values():
            learner["curve"] += [{"env_steps": st, "success": 0.5, "spl": 0.5, "collisions": 0.0}
                                 for st in (5_120, 60_160, 180_224)]  # fmt: skip
            learner["curve"].sort(key=lambda r: r["env_steps"])
    return {"args": {"steps": 600_000, "seed": 0, "pairs": 500, "eval_seed": 2024, "reach": [0.9, 0.99]},
            "scenes": scenes, "command": "python bench/bench_tabular.py ", "machine": {"start": {}}}  # fmt: skip


def test_the_learning_curves_show_the_checkpoints_the_marker_names_every_scene_side_by_side(pages, tmp_path, capsys):
    pages.renders_the_page(tmp_path, capsys, PAGE, "tabular-curves", bench_tabular(pages), ("0.614", "0.624"))


def test_the_learners_table_gives_the_steps_to_each_success_level_in_thousands(pages, tmp_path, capsys):
    pages.renders_the_page(tmp_path, capsys, PAGE, "tabular-learners", bench_tabular(pages), ("292.5", "299.5"))


def test_the_benchmarks_own_report_still_reads_the_json(pages):
    md = pages.results_pages.bench("bench_tabular_report.py", "markdown")
    data = bench_tabular(pages)
    for scene in data["scenes"].values():
        scene["datasets"] = {"blueprint": "b", "dynamic": "d"}
        scene["ambiguity"] = {"blueprint": {"free_cells": 1, "shared": 0, "no_radio": 0, "mislocalised": 0,
                                            "mean_error_cells": 0.0}}  # fmt: skip
        for learner in scene["learners"].values():
            learner["final"]["blueprint/fingerprint"] = learner["final"]["blueprint/-"]
    assert "| 600,064 | 0.614 / 0.589 |" in md(data)


COLUMNS = {"data ceiling": "ceiling", "CE": "ce", "VI-LCB": "lcb", "Π_b-SPIBB": "spibb",
           "**CE + senses**": "ce-senses", "**VI-LCB + senses**": "lcb-senses"}  # fmt: skip
VARIANTS = ("blueprint", "dynamic")


def offline_bench(scene: str, tabular: dict, summary: list) -> dict:
    """bench.json with the fields these tables read, and enough for the page's score tables of the same JSON."""
    behaviours = dict.fromkeys([*tabular, *(e["behaviour"] for e in summary)], {})
    config = {"scene": scene, "variants": list(VARIANTS), "sensing": "privileged"}
    algorithms = {e["algorithm"]: e["algorithm"] for e in summary}
    return {"config": config, "tabular": tabular, "summary": summary, "datasets": behaviours, "algorithms": algorithms}


def test_the_return_based_scores_set_blueprint_and_dynamic_in_one_cell(pages, tmp_path, capsys):
    text, block = pages.block_of(PAGE, "tabular-returns")
    head = [c.strip() for c in text[block.start : block.end].split("\n")[1].strip("|").split("|")]
    tabular = {}
    for beh, *cells in pages.rows_of(text, block):
        row = {"seconds": 5.0, "return_references": {}}
        for name, cell in zip(head[1:], cells, strict=True):
            row[COLUMNS[name]] = {v: {"return_normalized": x, "normalized": 1.0} for v, x in zip(VARIANTS, two(cell))}
        tabular[beh] = row
    data = offline_bench("dallas-q3", tabular, [])
    renders_several(pages, tmp_path, capsys, "tabular-returns", [data], (0, "83.6", "85.6"))  # the score tables change


def test_the_tables_with_senses_set_each_scenes_tables_beside_its_best_deep_learner(pages, tmp_path, capsys):
    text, block = pages.block_of(PAGE, "tabular-senses")
    head = [c.strip() for c in text[block.start : block.end].split("\n")[1].strip("|").split("|")]
    runs: dict[str, tuple[dict, list]] = {"dallas-q3": ({}, []), "cubicle": ({}, [])}
    for name, *cells in pages.rows_of(text, block):
        scene, beh = name.split(" ")
        tabular, summary = runs[scene]
        row = {"seconds": 5.0, "ceiling": {v: {"normalized": 100.0} for v in VARIANTS}}
        for col, cell in zip(head[1:-1], cells[:-1], strict=True):
            row[COLUMNS[col]] = {v: {"normalized": x, "return_normalized": 1.0} for v, x in zip(VARIANTS, two(cell))}
        tabular[beh] = row
        best = two(cells[-1])
        for algorithm, less in (("cql", 0.0), ("bc", 3.0)):  # the best, and one below it
            scores = {v: {"normalized": {"mean": x - less, "std": 0.0, "n": 1}} for v, x in zip(VARIANTS, best)}
            summary.append({"behaviour": beh, "algorithm": algorithm, **scores})
    datas = []
    for scene, (tabular, summary) in runs.items():
        datas += [offline_bench(scene, tabular, []), offline_bench(scene, {}, summary)]
    renders_several(pages, tmp_path, capsys, "tabular-senses", datas, (3, "64.2", "66.2"))
