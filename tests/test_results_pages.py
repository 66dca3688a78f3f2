"""tools/results_pages.py (make results-pages): a marked block of a docs page is re-rendered from its benchmark's
JSON, the rest of the page is kept byte for byte, --check reports a stale page, and a block whose JSON is absent
stays as it is with the command that would make it."""

import importlib.util
import json
import shutil
import sys
from pathlib import Path

import pytest

from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench
from dtradar_rl.experiments.offline_report import score_table

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("results_pages", ROOT / "tools" / "results_pages.py")
results_pages = importlib.util.module_from_spec(spec)
sys.modules["results_pages"] = results_pages  # dataclasses look their module up there
spec.loader.exec_module(results_pages)

BEFORE = "# Results\n\nProse above, with a table the tool must not touch:\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n"
MARKER = "<!-- results: offline-bench-scores bench/bench.json variant=blueprint -->\n"
OLD = "\n| dataset | numbers of an earlier run |\n|---|---|\n| random | 1.0 |\n\n"
AFTER = "<!-- end results -->\n\nProse below, untouched.   \nTrailing spaces and all.\n"


@pytest.fixture(scope="module")
def bench_dir(tmp_path_factory):
    """A tiny offline benchmark (one dataset, one algorithm, one seed, no tabular rows) on a synthetic twin, run once
    for the module: its folder holds bench.json."""
    tmp = tmp_path_factory.mktemp("results_pages")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DTRADAR_DATA_ROOT", str(tmp / "root"))
        cfg = OfflineBenchConfig(
            scene="synthetic-8x6",
            behaviours=("random",),
            algorithms=("bc",),
            seeds=(0,),
            steps=200,
            n_steps=5,
            num_envs=8,
            pairs=8,
            workers=1,
            fqe=False,
            tabular=False,
            out=str(tmp / "bench"),
            verbose=False,
        )
        result = run_bench(cfg)
    return tmp, result


@pytest.fixture()
def page(bench_dir, tmp_path):
    """A page with one marked block in a folder holding the benchmark's folder (the markers' root)."""
    src, result = bench_dir
    shutil.copytree(src / "bench", tmp_path / "bench")
    path = tmp_path / "page.md"
    path.write_text(BEFORE + MARKER + OLD + AFTER, encoding="utf-8")
    return path, result


def test_a_marked_block_becomes_the_benchmarks_table_and_the_text_around_it_is_kept_byte_for_byte(page, capsys):
    path, result = page
    assert results_pages.main(["--root", str(path.parent), str(path)]) == 0
    text = path.read_text(encoding="utf-8")
    table = "\n".join(score_table(result, "blueprint"))
    assert text == BEFORE + MARKER + "\n" + table + "\n\n" + AFTER
    assert "DiscreteBC" in table and "numbers of an earlier run" not in text
    assert "page.md:9 offline-bench-scores bench/bench.json: updated" in capsys.readouterr().out


def test_a_second_run_changes_nothing(page, capsys):
    path, _ = page
    results_pages.main(["--root", str(path.parent), str(path)])
    first = path.read_bytes()
    capsys.readouterr()
    assert results_pages.main(["--root", str(path.parent), str(path)]) == 0
    assert path.read_bytes() == first
    assert capsys.readouterr().out.strip().endswith(": unchanged")
    assert results_pages.main(["--check", "--root", str(path.parent), str(path)]) == 0


def test_check_reports_a_stale_page_and_writes_nothing(page, capsys):
    path, _ = page
    before = path.read_bytes()
    assert results_pages.main(["--check", "--root", str(path.parent), str(path)]) == 1
    captured = capsys.readouterr()
    assert ": out of date" in captured.out and "make results-pages" in captured.err
    assert path.read_bytes() == before


def test_a_missing_json_leaves_the_block_and_says_which_command_makes_it(page, capsys):
    path, _ = page
    shutil.rmtree(path.parent / "bench")
    before = path.read_bytes()
    assert results_pages.main(["--root", str(path.parent), str(path)]) == 0
    assert results_pages.main(["--check", "--root", str(path.parent), str(path)]) == 0
    assert path.read_bytes() == before
    out = capsys.readouterr().out
    assert "skipped: JSON not found: bench/bench.json (made by: python -m dtradar_rl offline-bench --out bench" in out


def test_a_table_of_several_runs_reads_every_json_its_marker_names_in_order(tmp_path, capsys, monkeypatch):
    seen = []

    def render(runs, options):
        seen.append(runs)
        return "| run | x |\n|---|---|\n" + "".join(f"| {r['name']} | {r['x']} |\n" for r in runs)

    renderer = results_pages.Renderer(render, "python bench/x.py --out {json}", several=True)
    monkeypatch.setitem(results_pages.RENDERERS, "runs", renderer)
    for name, x in (("b", 2), ("a", 1)):
        (tmp_path / f"{name}.json").write_text(json.dumps({"name": name, "x": x}), encoding="utf-8")
    page = tmp_path / "page.md"
    page.write_text(
        "<!-- results: runs b.json,a.json,c.json -->\n\n| old |\n\n<!-- end results -->\n", encoding="utf-8"
    )
    assert results_pages.main(["--root", str(tmp_path), str(page)]) == 0
    assert "skipped: JSON not found: c.json" in capsys.readouterr().out and not seen  # one run missing: kept
    page.write_text(page.read_text().replace(",c.json", ""), encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(page)]) == 0
    assert "| b | 2 |\n| a | 1 |" in page.read_text() and [r["name"] for r in seen[0]] == ["b", "a"]
    page.write_text("<!-- results: bench-rt a.json,b.json -->\n\n| old |\n\n<!-- end results -->\n", encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(page)]) == 2
    assert "renderer bench-rt reads one JSON, the marker names several" in capsys.readouterr().err


def test_a_corner_option_puts_the_pages_name_for_the_table_in_its_first_header_cell(page):
    path, result = page
    path.write_text(MARKER.replace(" -->", ' corner="random → blueprint" -->') + OLD + AFTER, encoding="utf-8")
    results_pages.main(["--root", str(path.parent), str(path)])
    header = score_table(result, "blueprint")[0]
    assert "| random → blueprint |" + header.split("|", 2)[2] in path.read_text(encoding="utf-8")


def test_a_marker_naming_no_renderer_or_never_closed_is_refused_with_the_fix(tmp_path, capsys):
    path = tmp_path / "page.md"
    path.write_text("<!-- results: no-such-bench x.json -->\n\n| a |\n\n<!-- end results -->\n", encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(path)]) == 2
    assert "no results renderer 'no-such-bench'" in capsys.readouterr().err
    path.write_text("<!-- results: offline-bench-scores x.json variant=blueprint -->\n\n| a |\n", encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(path)]) == 2
    assert "never closed" in capsys.readouterr().err


def test_the_table_option_keeps_one_table_of_a_renderers_output():
    md = "# heading\n\n| a |\n|---|\n| 1 |\n\ntext\n\n| b |\n|---|\n| 2 |\n"
    assert results_pages.nth_table(md, 2) == "| b |\n|---|\n| 2 |\n"
    with pytest.raises(results_pages.InvalidSettingError, match="table=1..2"):
        results_pages.nth_table(md, 3)


def test_every_marker_of_the_docs_names_a_renderer_with_its_options():
    """The committed pages parse: a typo in a marker fails here, not on the next benchmark's re-run."""
    found = []
    for page in sorted((ROOT / "docs").glob("**/*.md")):
        found += results_pages.blocks(page.read_text(encoding="utf-8"), str(page))
    assert any(b.renderer == "bench-radio" for b in found)


def test_a_marker_shown_in_a_code_block_is_an_example_not_a_block(page):
    path, _ = page
    example = "```markdown\n" + MARKER + "\n| dataset | ... |\n\n" + results_pages.END + "\n```\n\n"
    path.write_text(example + MARKER + OLD + AFTER, encoding="utf-8")
    (block,) = results_pages.blocks(path.read_text(encoding="utf-8"))
    assert block.line == example.count("\n") + 1
    results_pages.main(["--root", str(path.parent), str(path)])
    assert path.read_text(encoding="utf-8").startswith(example)


def test_a_flag_of_a_marker_is_yes_or_no(tmp_path, capsys):
    path = tmp_path / "page.md"
    path.write_text(
        "<!-- results: bench-latency x.json goal=maybe -->\n\n| a |\n\n<!-- end results -->\n", encoding="utf-8"
    )
    assert results_pages.main(["--root", str(tmp_path), str(path)]) == 2
    assert "goal=maybe: a flag is yes or no" in capsys.readouterr().err


# The benchmarks whose tables were marked after the fact: a JSON holding the numbers of the page's table is written
# by hand in the shape of the benchmark's writer (the runs' own JSONs are not kept), and the benchmark's renderer must
# give the page's block back byte for byte (so marking the table changed nothing, and a re-run changes only numbers).


def _block(page: str, marker: str) -> tuple[str, object]:
    """The committed page's text and its one block whose marker line holds ``marker``."""
    text = (ROOT / "docs" / "results" / page).read_text(encoding="utf-8")
    lines = text.splitlines()
    (block,) = [b for b in results_pages.blocks(text, page) if f"results: {marker}" in lines[b.line - 1]]
    return text, block


def _rows(text: str, block) -> list[list[str]]:
    """The cells of the block's table rows (header and separator left out)."""
    lines = [line for line in text[block.start : block.end].splitlines() if line.startswith("|")][2:]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines]


def _num(cell: str) -> float:
    return float(cell.replace(",", "").replace(" ", "").rstrip("%×xdBms").strip())


def _renders_the_page(tmp_path, capsys, page: str, marker: str, data: dict, change: tuple[str, str]) -> None:
    """``data`` at the block's JSON path gives the page's block unchanged; a re-run's new number lands in it."""
    text, block = _block(page, marker)
    copy = tmp_path / page
    copy.write_text(text, encoding="utf-8")
    json_path = tmp_path / block.json
    json_path.parent.mkdir(parents=True, exist_ok=True)
    json_path.write_text(json.dumps(data), encoding="utf-8")
    label = f"{page}:{block.line} {block.renderer} {block.json}"
    results_pages.main(["--check", "--root", str(tmp_path), str(copy)])  # another block of the JSON may differ
    assert f"{label}: unchanged" in capsys.readouterr().out
    old, new = change  # a number of the page, and what a re-run measured instead
    json_path.write_text(json.dumps(data).replace(old, new, 1), encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(copy)]) == 0
    assert f"{label}: updated" in capsys.readouterr().out
    after = copy.read_text(encoding="utf-8")
    was = text[block.start : block.end]
    now = after[block.start : after.index("\n" + results_pages.END, block.start) + 1]
    assert now.split("\n")[1:3] == was.split("\n")[1:3]  # the page's header and separator
    assert new in now and new not in was and after[: block.start] == text[: block.start]


def test_bench_rt_renders_the_ray_tracing_pages_table_from_its_json_alone(tmp_path, capsys):
    text, block = _block("ray-tracing.md", "bench-rt results/bench_rt_stock.json")
    keys = ("samples_per_src", "seconds", "cells_per_s", "agreement", "found_path_share", "paths_found_vs_reference")
    rows = []
    for cells in _rows(text, block):
        row = dict(zip(keys, map(_num, cells), strict=False))
        for k in ("agreement", "found_path_share", "paths_found_vs_reference"):
            row[k] /= 100
        row["samples_per_src"] = int(row["samples_per_src"])
        rows.append({**row, "median_abs_gain_error_db": _num(cells[6]), "speedup_vs_reference": _num(cells[7])})
    data = {
        "scene": "cubicle/blueprint",
        "free_cells": 592,
        "max_depth": 5,
        "machine": "2-core CPU, no GPU (LLVM backend)",
        "reference_samples": 1_000_000,
        "reference_path_buffer": 10_000_000,
        "path_buffer": 1_000_000,
        "reference_seconds": 136.6,
        "first_call_seconds_incl_jit": 2.3,
        "rows": rows,
    }
    _renders_the_page(tmp_path, capsys, "ray-tracing.md", "bench-rt", data, ("1480.3", "1500.0"))
    md = results_pages._bench("bench_rt.py", "markdown")(data)
    assert "Reference: 1e+06 samples (path buffer 1e+07), 136.6 s (4 cells/s)" in md  # the page's sentence above


def test_bench_threads_renders_the_speed_pages_threads_table(tmp_path, capsys):
    def case(load, threads, each, median, steps):
        return {"load": load, "threads": threads, "wall_s_each": each, "median_wall_s": median,
                "median_steps_per_s": steps, "updates": 100}  # fmt: skip

    data = {
        "scene": "cubicle",
        "preset": "memory-escape-noise",
        "steps": 30_000,
        "rounds": 3,
        "busy_rounds": 1,
        "machine": {},
        "cases": [
            case("idle", 1, [7.93, 7.1, 6.92], 7.1, 4262),
            case("idle", 2, [5.46, 4.33, 5.27], 5.27, 5746),
            case("one busy process", 1, [7.4], 7.4, 4084),
            case("one busy process", 2, [19.1], 19.1, 1580),
        ],
    }
    _renders_the_page(tmp_path, capsys, "speed.md", "bench-threads", data, ("7.93", "8.4"))


def test_bench_latency_renders_the_speed_pages_table_without_the_goal_column(tmp_path, capsys):
    text, block = _block("speed.md", "bench-latency")
    rows = []
    for policy, threads, load, p50, p99, _ in _rows(text, block):
        for run, (a, b) in enumerate(zip(p50.split(), p99.split(), strict=True)):
            rows.append({"policy": policy, "threads": int(threads), "load": load, "run": run,
                         "p50_ms": float(a), "p99_ms": float(b)})  # fmt: skip
    data = {"scene": "cubicle", "decisions": 1000, "rows": rows, "machine": {"start": {}, "end": {}}}
    _renders_the_page(tmp_path, capsys, "speed.md", "bench-latency", data, ("0.057", "0.051"))
    assert "goal met" in results_pages._bench("bench_latency.py", "markdown")(data)  # the flag's default: yes


def test_bench_rl_renders_the_speed_pages_headline_without_the_throughput_rows(tmp_path, capsys):
    data = {
        "dataset": {"name": "cubicle/blueprint", "synthetic": False},
        "machine": {"torch_threads": 1, "load_1min_before": 0.1},
        "env_steps_per_s": {"gymnasium": 48_300.0, "batched_4096": 17_300_000.0},
        "decision_latency_ms": 0.042,
        "decision_speedup_vs_paper": 400.0,
        "train": {
            "env_steps": 600_064,
            "wall_s": 47.8,
            "speedup_vs_paper": 58.0,
            "goal_met": True,
            "speedup_vs_sb3": 8.1,
        },  # fmt: skip
        "train_robust": {"config": {"aug_obstacles": 10}, "wall_s": 54.1},
        "sb3": {"wall_s_for_budget": 386.0, "env_steps": 466_665, "capped": True, "threads": 1},
        "eval": [],
    }
    _renders_the_page(tmp_path, capsys, "speed.md", "bench-rl results/bench_rl.json table=1", data, ("47.8", "49.0"))
    assert "env steps/s" in results_pages._bench("bench_rl_report.py", "render_markdown")(data)
