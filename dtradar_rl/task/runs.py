"""Where runs go: every default output path of a job is built here, so ``runs/`` has one definition.

runs/<scene>/dqn/model.pt            make train (config.json, curves.csv, curves.png, last.pt beside it)
runs/<scene>/eval/                   make eval
runs/<scene>/adapt/                  make adapt
runs/<scene>/offline/<algorithm>/    make offline
runs/paper/  runs/sweep/  runs/cross/
"""

from __future__ import annotations

from pathlib import Path

RUNS = Path("runs")


def run_dir(*parts: str) -> Path:
    """``runs/<part>/<part>/...`` (relative to the working directory, as every job's ``--out`` default)."""
    return RUNS.joinpath(*parts)


def dqn_checkpoint(scene: str) -> Path:
    """The ``model.pt`` that ``make train SCENE=<scene>`` writes and ``make eval``/``adapt``/``logged`` read."""
    return run_dir(scene, "dqn", "model.pt")
