"""The committed cards of the built-in datasets, in ``cards/<scene>/<variant>/``.

Each holds ``card.json`` (the newest stored version's ``meta.json``, its tag and the version history: the card's only
input), ``README.md`` (rendered from ``card.json`` by :func:`dtradar_data.store.card.render_card`) and its pictures
(``cells.png``, the table itself, and ``coverage.png``, Sionna's radio map). ``python -m dtradar_data cards`` refreshes
them from the local store; ``--check`` (and the test suite) re-renders every committed ``card.json`` and fails when
``README.md`` differs, so a template or metadata change without ``make cards`` is caught without needing the datasets
themselves.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from dtradar_data.core import layout as P
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    DtradarError,
)
from dtradar_data.store import listing, local
from dtradar_data.store.card import CITY_FILE, history_entry, render_card

CARD_INPUTS = "card.json"


def render_inputs(inputs: dict[str, Any]) -> str:
    return render_card(inputs["meta"], tag=inputs.get("tag"), history=inputs.get("history") or [])


def snapshot(name: str, out_dir: Path) -> Path:
    """Write ``out_dir/<scene>/<variant>/{card.json, README.md}`` and the pictures the version holds (``cells.png``,
    ``coverage.png``, ``city.png``, ``moving.gif``) from the newest stored version."""
    _, version, vdir = local.resolve(name)
    entries = listing.history(name)
    meta = local.read_meta(vdir)
    tag = next((t for t, m in entries if m.get("version") == version), None)
    # History up to the snapshotted version: later untagged/pulled versions are not part of its story.
    upto = [history_entry(t, m) for t, m in entries]
    upto = upto[: next((i + 1 for i, h in enumerate(upto) if h["version"] == version), len(upto))]
    inputs = {"tag": tag, "meta": meta, "history": upto}
    target = out_dir / meta["scene"] / meta["variant"]
    target.mkdir(parents=True, exist_ok=True)
    (target / CARD_INPUTS).write_text(json.dumps(inputs, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
    (target / P.CARD_FILE).write_text(render_inputs(inputs))
    for picture in (P.CELLS_PICTURE_FILE, P.COVERAGE_FILE, CITY_FILE, P.MOVING_GIF_FILE):  # the images the card shows
        if (vdir / picture).is_file():
            shutil.copyfile(vdir / picture, target / picture)
    return target


def write_builtin_cards(out_dir: Path, names: list[str] | None = None) -> tuple[list[Path], list[str]]:
    """Refresh the committed cards of ``names`` (default: every built-in dataset); returns (written, skipped)."""
    entries = listing.list_datasets()
    wanted = names or [e.name for e in entries if e.builtin]
    written, skipped = [], []
    for name in wanted:
        try:
            written.append(snapshot(name, out_dir))
        except DatasetNotFoundError:
            skipped.append(name)  # not built here: its committed card (if any) is left as it is
    return written, skipped


class CardsNotFoundError(DtradarError, FileNotFoundError):
    """A cards folder that does not exist or holds no committed card."""


def committed_cards(cards_dir: Path) -> list[Path]:
    return sorted(p.parent for p in cards_dir.glob(f"*/*/{CARD_INPUTS}"))


def _require_cards(cards_dir: Path) -> list[Path]:
    """The committed cards, or :class:`CardsNotFoundError`: checking nothing must not pass as "up to date"."""
    found = committed_cards(cards_dir) if cards_dir.is_dir() else []
    if not found:
        why = (
            "no such folder"
            if not cards_dir.exists()
            else ("not a folder" if not cards_dir.is_dir() else f"no <scene>/<variant>/{CARD_INPUTS} in it")
        )
        raise CardsNotFoundError(
            f"--out {cards_dir}: no committed cards ({why})",
            hint="pass the folder that holds <scene>/<variant>/card.json (default: cards), "
            "or write the cards first with `make cards`",
        )
    return found


def _read_inputs(card_dir: Path) -> dict[str, Any]:
    path = card_dir / CARD_INPUTS
    try:
        inputs = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise CorruptDatasetError(
            f"{path} is not valid JSON ({exc})", hint="restore it from git, or rewrite it with `make cards`"
        ) from exc
    if not isinstance(inputs, dict) or not isinstance(inputs.get("meta"), dict):
        raise CorruptDatasetError(f"{path} has no 'meta' record", hint="restore it from git, or `make cards`")
    return inputs


def stale_cards(cards_dir: Path) -> list[Path]:
    """Card directories whose ``README.md`` differs from what their ``card.json`` renders to now."""
    stale = []
    for d in _require_cards(cards_dir):
        inputs = _read_inputs(d)
        readme = d / P.CARD_FILE
        if not readme.is_file() or readme.read_text() != render_inputs(inputs):
            stale.append(d)
    return stale


def rerender(cards_dir: Path) -> list[Path]:
    """Re-render every committed card from its ``card.json`` (after a template change, no datasets needed)."""
    out = []
    for d in _require_cards(cards_dir):
        (d / P.CARD_FILE).write_text(render_inputs(_read_inputs(d)))
        out.append(d)
    return out
