"""What every renderer registry of tools/results_pages.py shares: the Renderer record and how a benchmark's own
JSON -> Markdown function is imported (never re-written here)."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]


def bench(script: str, func: str) -> Callable[..., Any]:
    """``func`` of ``bench/<script>``, imported by path on first use (bench/ is no package; its scripts import their
    report modules beside them, hence bench/ on the path)."""
    folder = ROOT / "bench"
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
    name = Path(script).stem
    loaded = sys.modules.get(name)
    if loaded is None:
        spec = importlib.util.spec_from_file_location(name, folder / script)
        assert spec and spec.loader
        loaded = importlib.util.module_from_spec(spec)
        sys.modules[name] = loaded
        spec.loader.exec_module(loaded)
    return getattr(loaded, func)


def module(path: str, func: str) -> Callable[..., Any]:
    """``func`` of the importable module ``path`` (the packages' own renderers, e.g. the offline benchmark's)."""
    return getattr(importlib.import_module(path), func)


def lines(out: str | list[str]) -> str:
    """A renderer's output as text: some return their lines."""
    return out if isinstance(out, str) else "\n".join(out) + "\n"


@dataclass(frozen=True)
class Renderer:
    """How one kind of JSON becomes Markdown, and the command that writes that JSON (``{json}``, ``{dir}``,
    ``{stem}`` and ``{name}`` filled from the block's first JSON path).

    A table assembled from several runs (one per row or per column: seeds, presets, scenes) has ``several=True``:
    its marker names every run's JSON, comma-separated and in the table's order, and ``render`` gets their list."""

    render: Callable[[Any, dict[str, str]], str]
    command: str
    options: tuple[str, ...] = field(default=())  # each marker names them
    flags: tuple[str, ...] = field(default=())  # yes (the default) or no: a part of the output a page leaves out
    several: bool = False
