"""Where runs go: every default output path of a job is built here, so ``runs/`` has one definition.

runs/<scene>/dqn/model.pt            make train (config.json, curves.csv, curves.png, last.pt beside it)
runs/<scene>/eval/                   make eval
runs/<scene>/adapt/                  make adapt
runs/<scene>/offline/<algorithm>/    make offline
runs/paper/  runs/sweep/  runs/cross/
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

RUNS = Path("runs")


def run_dir(*parts: str) -> Path:
    """``runs/<part>/<part>/...`` (relative to the working directory, as every job's ``--out`` default)."""
    return RUNS.joinpath(*parts)


def dqn_checkpoint(scene: str) -> Path:
    """The ``model.pt`` that ``make train SCENE=<scene>`` writes and ``make eval``/``adapt``/``logged`` read."""
    return run_dir(scene, "dqn", "model.pt")


@contextmanager
def no_empty_folder_on_failure(path: str | Path) -> Iterator[Path]:
    """Run the block; when it fails, remove the folders of ``path`` it created (``path`` and the missing parents
    above it) that it left empty, so a failed job leaves no empty ``--out`` behind. Folders that existed before,
    or that hold anything, stay."""
    path = Path(path)
    missing = []
    p = path
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    try:
        yield path
    except BaseException:
        for folder in missing:  # deepest first
            try:
                folder.rmdir()  # only an empty folder goes
            except OSError:
                break
        raise
