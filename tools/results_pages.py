"""Regenerate the marked tables of the docs' results pages from the benchmarks' JSON.

A block on a page is marked by two HTML comments (invisible on the site)::

    <!-- results: offline-bench-scores results/offline_bench/cubicle/bench.json variant=blueprint -->

    | dataset | ... |

    <!-- end results -->

The first word names a renderer (``RENDERERS`` below: each is the benchmark's own JSON -> Markdown function,
imported, never re-written here), the second the JSON, relative to the repository root; ``key=value`` options
follow (``table=N`` keeps the Nth table of the renderer's output, ``corner="..."`` replaces the first cell of its
header, where a page names the table there; the others go to the renderer: its named options, and its yes/no flags,
``yes`` unless the marker says ``no``, e.g. ``throughput=no`` where a page leaves those rows out). Every block whose
JSON exists is replaced by the renderer's output; a block whose JSON is absent is left as it is (the pages keep the
numbers of the run they were written from). One line per block says what happened::

    .venv/bin/python tools/results_pages.py          # rewrite the pages (make results-pages)
    .venv/bin/python tools/results_pages.py --check  # exit 1 when a page would change
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import re
import shlex
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the project's packages import from the checkout
    sys.path.insert(0, str(ROOT))

from dtradar_data.core.errors import InvalidSettingError, UnknownNameError  # noqa: E402
from dtradar_data.core.files import write_atomic  # noqa: E402

#: The pages searched when none is named: every docs page (the results pages hold the blocks today).
PAGES_GLOB = "docs/**/*.md"
#: Options every renderer takes, applied to its output here: which table, and the header's first cell.
GENERIC = ("table", "corner")
START = re.compile(r"^<!-- results: (?P<spec>.*?) -->[ \t]*$", re.M)
END = "<!-- end results -->"
FENCE = re.compile(r"^[ \t]*(```+|~~~+)", re.M)


def _bench(script: str, func: str) -> Callable[..., Any]:
    """``func`` of ``bench/<script>``, imported by path on first use (bench/ is no package; its scripts import their
    report modules beside them, hence bench/ on the path)."""
    bench = ROOT / "bench"
    if str(bench) not in sys.path:
        sys.path.insert(0, str(bench))
    name = Path(script).stem
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, bench / script)
        assert spec and spec.loader
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return getattr(module, func)


def _module(path: str, func: str) -> Callable[..., Any]:
    return getattr(importlib.import_module(path), func)


def _lines(out: str | list[str]) -> str:
    return out if isinstance(out, str) else "\n".join(out) + "\n"


@dataclass(frozen=True)
class Renderer:
    """How one kind of JSON becomes Markdown, and the command that writes that JSON (``{json}``, ``{dir}``,
    ``{stem}`` and ``{name}`` filled from the block's JSON path)."""

    render: Callable[[dict[str, Any], dict[str, str]], str]
    command: str
    options: tuple[str, ...] = field(default=())  # each marker names them
    flags: tuple[str, ...] = field(default=())  # yes (the default) or no: a part of the output a page leaves out


#: name -> renderer. Each calls the benchmark's own renderer, so a page block is what the benchmark's .md holds.
RENDERERS: dict[str, Renderer] = {
    "bench-radio": Renderer(
        lambda d, o: _bench("bench_radio.py", "markdown")(d),
        'make bench-radio ARGS="--out {stem}" (several runs: python bench/bench_radio.py --merge <their .json> '
        "--out {stem})",
    ),
    "bench-nav": Renderer(
        lambda d, o: _bench("bench_nav.py", "markdown")(d),
        'make bench-nav ARGS="--out {dir} --name {name}" (with the scenes and options the page names)',
    ),
    "bench-rl": Renderer(
        lambda d, o: _bench("bench_rl_report.py", "render_markdown")(d, throughput=o["throughput"] == "yes"),
        "make bench-rl (results/bench_rl.json; --scene <scene>: results/bench_rl_<scene>.json)",
        flags=("throughput",),
    ),
    "bench-latency": Renderer(
        lambda d, o: _bench("bench_latency.py", "markdown")(d, goal=o["goal"] == "yes"),
        'make bench-latency SCENE=<scene> ARGS="--out {dir}" (writes {dir}/bench_latency_<scene>.json)',
        flags=("goal",),
    ),
    "bench-threads": Renderer(
        lambda d, o: _bench("bench_threads.py", "markdown")(d),
        'make bench-threads SCENE=<scene> ARGS="--out {dir}" (writes {dir}/bench_threads_<scene>.json)',
    ),
    "bench-rt": Renderer(
        lambda d, o: _bench("bench_rt.py", "markdown")(d),
        'make bench-rt ARGS="--out {dir}" (with the options the page names; --scene, --buffer and --stock-solver '
        "name the file: {name}.json)",
    ),
    "bench-moving": Renderer(
        lambda d, o: _bench("bench_moving_report.py", "markdown")(d),
        'make bench-moving SCENES=<scene> ARGS="--out {dir}" (writes {dir}/bench_moving_<scene>.json)',
    ),
    "bench-offline-speed": Renderer(
        lambda d, o: _bench("bench_offline_speed_report.py", "markdown")(d),
        'make bench-offline-speed ARGS="--out {stem}"',
    ),
    "offline-bench": Renderer(
        lambda d, o: _module("dtradar_rl.experiments.offline_report", "markdown")(d),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
    ),
    "offline-bench-scores": Renderer(
        lambda d, o: _lines(_module("dtradar_rl.experiments.offline_report", "score_table")(d, o["variant"])),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
        ("variant",),
    ),
    "offline-bench-returns": Renderer(
        lambda d, o: _lines(_module("dtradar_rl.experiments.offline_report", "return_table")(d, o["variant"])),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
        ("variant",),
    ),
}


@dataclass(frozen=True)
class Block:
    """One marked block: where its content lies in the page's text, and what it is made from."""

    line: int
    renderer: str
    json: str
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
    data = json.loads((root / block.json).read_text(encoding="utf-8"))
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


def command_for(block: Block) -> str:
    """The command that writes the block's JSON."""
    path = Path(block.json)
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
        if not (root / b.json).is_file():
            say(f"{label}: skipped: JSON not found (made by: {command_for(b)})")
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
