"""Regenerate the marked tables of the docs' results pages from the benchmarks' JSON.

A block on a page is marked by two HTML comments (invisible on the site)::

    <!-- results: offline-bench-scores results/offline_bench/cubicle/bench.json variant=blueprint -->

    | dataset | ... |

    <!-- end results -->

The first word names a renderer (the ``RENDERERS`` of the modules of tools/renderers/: each is the benchmark's own
JSON -> Markdown function, imported, never re-written here), the second the JSON, relative to the repository root
(a table assembled from several runs names each run's JSON, comma-separated, in the table's order); ``key=value``
options follow (``table=N`` keeps the Nth table of the renderer's output, ``corner="..."`` replaces the first cell
of its header, where a page names the table there; the others go to the renderer: its named options, and its yes/no
flags, ``yes`` unless the marker says ``no``, e.g. ``throughput=no`` where a page leaves those rows out). Every
block whose JSON exists is replaced by the renderer's output; a block whose JSON is absent is left as it is (the
pages keep the numbers of the run they were written from). One line per block says what happened::

    .venv/bin/python tools/results_pages.py          # rewrite the pages (make results-pages)
    .venv/bin/python tools/results_pages.py --check  # exit 1 when a page would change
"""

from __future__ import annotations

import argparse
import importlib
import json
import re
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the project's packages import from the checkout
    sys.path.insert(0, str(ROOT))

if str(ROOT / "tools") not in sys.path:  # the renderer registries, tools/renderers/
    sys.path.insert(0, str(ROOT / "tools"))

from renderers.base import Renderer, bench  # noqa: E402

from dtradar_data.core.errors import InvalidSettingError, UnknownNameError  # noqa: E402
from dtradar_data.core.files import write_atomic  # noqa: E402

#: The pages searched when none is named: every docs page (the results pages hold the blocks today).
PAGES_GLOB = "docs/**/*.md"
#: Options every renderer takes, applied to its output here: which table, and the header's first cell.
GENERIC = ("table", "corner")
START = re.compile(r"^<!-- results: (?P<spec>.*?) -->[ \t]*$", re.M)
END = "<!-- end results -->"
FENCE = re.compile(r"^[ \t]*(```+|~~~+)", re.M)


def _registries() -> dict[str, Renderer]:
    """Every renderer: the ``RENDERERS`` of each module of tools/renderers/ (one per benchmark family or results page),
    merged; a name defined twice is a mistake caught here."""
    merged: dict[str, Renderer] = {}
    for path in sorted((ROOT / "tools" / "renderers").glob("*.py")):
        if path.stem in ("base", "__init__"):
            continue
        found = getattr(importlib.import_module(f"renderers.{path.stem}"), "RENDERERS", {})
        twice = sorted(set(found) & set(merged))
        if twice:
            raise RuntimeError(f"tools/renderers/{path.name} defines renderers already defined: {twice}")
        merged.update(found)
    return merged


#: name -> renderer.
RENDERERS: dict[str, Renderer] = _registries()
_bench = bench  # the tests call the benchmarks' renderers through this module


@dataclass(frozen=True)
class Block:
    """One marked block: where its content lies in the page's text, and what it is made from."""

    line: int
    renderer: str
    json: str  # the JSON path, or several comma-separated (a renderer with several=True)
    options: dict[str, str]
    start: int  # first character after the start marker's line
    end: int  # first character of the end marker


def _fenced(text: str) -> list[tuple[int, int]]:
    """The character spans of the text's fenced code blocks (a marker shown in one, as docs/development.md shows
    one, is an example, not a block)."""
    spans, opened = [], None
    for m in FENCE.finditer(text):
        if opened is None:
            opened = m
        elif m.group(1)[0] == opened.group(1)[0] and len(m.group(1)) >= len(opened.group(1)):
            spans.append((opened.start(), m.end()))
            opened = None
    return spans + ([(opened.start(), len(text))] if opened else [])


def blocks(text: str, where: str = "page") -> list[Block]:
    """The marked blocks of a page's text, in order; a malformed marker raises with the line to fix."""
    found, pos = [], 0
    fenced = _fenced(text)
    for m in START.finditer(text):
        if any(a <= m.start() < b for a, b in fenced):
            continue
        line = text.count("\n", 0, m.start()) + 1
        if m.start() < pos:
            raise InvalidSettingError(
                f"{where}:{line}: a results block starts inside the one before it",
                hint=f"close the block before it with a line '{END}'",
            )
        words = shlex.split(m.group("spec"))
        if len(words) < 2:
            raise InvalidSettingError(
                f"{where}:{line}: a results marker needs a renderer and a JSON path, got {m.group('spec')!r}",
                hint="write <!-- results: <renderer> <json path> [key=value ...] -->; renderers: "
                + ", ".join(RENDERERS),
            )
        name, path, rest = words[0], words[1], words[2:]
        if name not in RENDERERS:
            raise UnknownNameError(
                f"{where}:{line}: no results renderer {name!r}", hint="use one of " + ", ".join(RENDERERS)
            )
        bad = [w for w in rest if "=" not in w]
        if bad:
            raise InvalidSettingError(
                f"{where}:{line}: options of a results marker are key=value, got {bad}", hint="e.g. table=2"
            )
        options = dict(w.split("=", 1) for w in rest)
        r = RENDERERS[name]
        wanted = set(r.options) | set(r.flags) | set(GENERIC)
        if set(options) - wanted or set(r.options) - set(options):
            raise InvalidSettingError(
                f"{where}:{line}: renderer {name} takes the options {sorted(wanted)}, got {sorted(options)}",
                hint="name every one of "
                + (", ".join(r.options) or "none")
                + "; "
                + ", ".join((*r.flags, *GENERIC))
                + " are optional",
            )
        if "," in path and not r.several:
            raise InvalidSettingError(
                f"{where}:{line}: renderer {name} reads one JSON, the marker names several: {path}",
                hint="name one JSON path, or use a renderer of several runs",
            )
        bad = [f"{k}={options[k]}" for k in r.flags if options.get(k, "yes") not in ("yes", "no")]
        if bad:
            raise InvalidSettingError(
                f"{where}:{line}: {', '.join(bad)}: a flag is yes or no",
                hint=f"write {bad[0].split('=')[0]}=no to leave that part of the output out",
            )
        start = m.end() + 1
        end = text.find("\n" + END, m.end())
        if end < 0:
            raise InvalidSettingError(f"{where}:{line}: a results block is never closed", hint=f"add a line '{END}'")
        found.append(Block(line, name, path, options, start, end + 1))
        pos = end + 1
    return found


def nth_table(markdown: str, n: int) -> str:
    """The ``n``-th (1-based) pipe table of ``markdown``: its consecutive lines starting with ``|``."""
    tables: list[list[str]] = []
    previous = False
    for line in markdown.splitlines():
        inside = line.startswith("|")
        if inside and not previous:
            tables.append([])
        if inside:
            tables[-1].append(line)
        previous = inside
    if not 1 <= n <= len(tables):
        raise InvalidSettingError(
            f"table={n}, but the renderer wrote {len(tables)} table(s)", hint=f"use table=1..{len(tables)}"
        )
    return "\n".join(tables[n - 1]) + "\n"


def render(block: Block, root: Path) -> str:
    """The block's new content: a blank line, the renderer's Markdown, a blank line (so the markers never touch a
    table, which Markdown would otherwise read as part of it)."""
    loaded = [json.loads((root / p).read_text(encoding="utf-8")) for p in paths(block)]
    data = loaded if RENDERERS[block.renderer].several else loaded[0]
    options = dict.fromkeys(RENDERERS[block.renderer].flags, "yes")
    options.update((k, v) for k, v in block.options.items() if k not in GENERIC)
    try:
        out = RENDERERS[block.renderer].render(data, options)
    except (KeyError, TypeError, ValueError) as e:
        raise InvalidSettingError(
            f"renderer {block.renderer} cannot read {block.json}: {type(e).__name__}: {e}",
            hint="the JSON is not of the benchmark the marker names: fix the marker's renderer, or re-run the "
            "benchmark with this checkout",
        ) from e
    if "table" in block.options:
        out = nth_table(out, int(block.options["table"]))
    if "corner" in block.options:
        out = re.sub(r"^\| [^|]*\|", lambda _: f"| {block.options['corner']} |", out, count=1, flags=re.M)
    return "\n" + out.strip("\n") + "\n\n"


def paths(block: Block) -> list[str]:
    """The block's JSON paths, relative to the root (one, or several in the table's order)."""
    return [p for p in block.json.split(",") if p]


def command_for(block: Block) -> str:
    """The command that writes the block's JSON (the first of several)."""
    path = Path(paths(block)[0])
    stem = path.with_suffix("")
    return RENDERERS[block.renderer].command.format(json=path, dir=path.parent, stem=stem, name=stem.name)


def update_page(path: Path, root: Path, check: bool, say: Callable[[str], None] = print) -> bool:
    """Re-render every block of one page whose JSON exists (written atomically unless ``check``); True when the page
    changed (or would)."""
    text = path.read_text(encoding="utf-8")
    where = str(path.relative_to(root)) if path.is_relative_to(root) else str(path)
    parts, last = [], 0
    for b in blocks(text, where):
        label = f"{where}:{b.line} {b.renderer} {b.json}"
        missing = [p for p in paths(b) if not (root / p).is_file()]
        if missing:
            say(f"{label}: skipped: JSON not found: {', '.join(missing)} (made by: {command_for(b)})")
            continue
        new = render(b, root)
        if new == text[b.start : b.end]:
            say(f"{label}: unchanged")
            continue
        say(f"{label}: {'out of date' if check else 'updated'}")
        parts += [text[last : b.start], new]
        last = b.end
    if not parts:
        return False
    if not check:
        write_atomic(path, "".join(parts) + text[last:])
    return True


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pages", nargs="*", type=Path, help=f"pages to update (default: every {PAGES_GLOB})")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 when a page would change")
    ap.add_argument("--root", type=Path, default=ROOT, help="folder the markers' JSON paths are relative to")
    args = ap.parse_args(argv)
    root = args.root.resolve()
    pages = [p.resolve() for p in args.pages] or sorted(root.glob(PAGES_GLOB))
    try:
        changed = [p for p in pages if update_page(p, root, args.check)]
    except (InvalidSettingError, UnknownNameError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.check and changed:
        print("out of date (run make results-pages): " + ", ".join(str(p) for p in changed), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
