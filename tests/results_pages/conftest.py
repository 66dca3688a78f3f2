"""What the results pages' tests share: tools/results_pages.py imported as a module, and the check that a marked
table of a committed page is what its renderer makes of a JSON holding the page's numbers.

The tables were marked after their runs (the runs' own JSONs are not kept): a test writes, by hand, a JSON in the
shape of the benchmark's writer holding the numbers the page shows, and the renderer must give the page's block back
byte for byte (so marking the table changed nothing, and a re-run changes only numbers)."""

import importlib.util
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("results_pages", ROOT / "tools" / "results_pages.py")
results_pages = importlib.util.module_from_spec(spec)
sys.modules["results_pages"] = results_pages  # dataclasses look their module up there
spec.loader.exec_module(results_pages)


def block_of(page: str, marker: str) -> tuple[str, object]:
    """The committed page's text and its one block whose marker line holds ``marker``."""
    text = (ROOT / "docs" / "results" / page).read_text(encoding="utf-8")
    lines = text.splitlines()
    (block,) = [b for b in results_pages.blocks(text, page) if f"results: {marker}" in lines[b.line - 1]]
    return text, block


def rows_of(text: str, block) -> list[list[str]]:
    """The cells of the block's table rows (header and separator left out)."""
    lines = [line for line in text[block.start : block.end].splitlines() if line.startswith("|")][2:]
    return [[c.strip() for c in line.strip("|").split("|")] for line in lines]


def num(cell: str) -> float:
    return float(cell.replace(",", "").replace(" ", "").rstrip("%×xdBms").strip())


def renders_the_page(tmp_path, capsys, page: str, marker: str, data: dict, change: tuple[str, str]) -> None:
    """``data`` at the block's JSON path gives the page's block unchanged; a re-run's new number lands in it."""
    text, block = block_of(page, marker)
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


def renders_runs(tmp_path, capsys, page: str, marker: str, datas: list | dict, change: tuple) -> str:
    """The block (alone on a copy of the page: other blocks may read the same JSONs) rendered from its JSONs (the
    marker's paths, in order, hold ``datas``; one JSON: ``datas`` is it) is the page's, byte for byte; a re-run's new
    number lands in it: ``change`` = (which JSON, its old text, the new[, how the table shows the new]). Returns the
    new block."""
    text, block = block_of(page, marker)
    piece = text[text.rfind("\n", 0, block.start - 1) + 1 : block.end] + results_pages.END + "\n"
    (block,) = results_pages.blocks(piece, page)
    copy = tmp_path / page
    copy.write_text(piece, encoding="utf-8")
    paths = results_pages.paths(block)
    datas = datas if isinstance(datas, list) else [datas]
    assert len(paths) == len(datas)
    for p, d in zip(paths, datas, strict=True):
        (tmp_path / p).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / p).write_text(json.dumps(d), encoding="utf-8")
    was = piece[block.start : block.end]
    assert results_pages.render(block, tmp_path) == was
    label = f"{page}:{block.line} {block.renderer} {block.json}"
    assert results_pages.main(["--check", "--root", str(tmp_path), str(copy)]) == 0
    assert f"{label}: unchanged" in capsys.readouterr().out
    i, old, new, shown = (*change, change[-1])[:4]
    assert old in json.dumps(datas[i])
    (tmp_path / paths[i]).write_text(json.dumps(datas[i]).replace(old, new, 1), encoding="utf-8")
    assert results_pages.main(["--root", str(tmp_path), str(copy)]) == 0
    assert f"{label}: updated" in capsys.readouterr().out
    after = copy.read_text(encoding="utf-8")
    now = after[block.start : after.index("\n" + results_pages.END, block.start) + 1]
    assert after[: block.start] == piece[: block.start] and after.endswith(results_pages.END + "\n")
    assert now.split("\n")[1:3] == was.split("\n")[1:3]  # the page's header and separator
    assert shown in now and shown not in was
    return now


@pytest.fixture(scope="session")
def pages() -> SimpleNamespace:
    """The tool and the helpers above, for the tests of this folder (a conftest is not imported by name)."""
    return SimpleNamespace(
        results_pages=results_pages, ROOT=ROOT, block_of=block_of, rows_of=rows_of, num=num,
        renders_the_page=renders_the_page, renders_runs=renders_runs,
    )  # fmt: skip
