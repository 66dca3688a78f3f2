"""tools/results_pages.py (make results-pages): a marked block of a docs page is re-rendered from its benchmark's
JSON, the rest of the page is kept byte for byte, --check reports a stale page, and a block whose JSON is absent
stays as it is with the command that would make it."""

import json
import shutil
import sys
from pathlib import Path

import pytest

from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench
from dtradar_rl.experiments.offline_report import score_table

ROOT = Path(__file__).resolve().parents[2]
results_pages = sys.modules["results_pages"]  # tools/results_pages.py, loaded by this folder's conftest

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
