"""Where runs go: every default output path of a job is built here, so ``runs/`` has one definition; and how a job
holds its output folder while it writes it (:func:`held_out_folder`: one writer per folder).

runs/<scene>/agent/agent.json        make train: the default agent (radio filter; honest sensing)
runs/<scene>/dqn/model.pt            make train AGENT=dqn (config.json, curves.csv, curves.png, last.pt beside it)
runs/<scene>/eval/                   make eval
runs/<scene>/adapt/                  make adapt
runs/<scene>/offline/<algorithm>/    make offline
runs/paper/  runs/sweep/  runs/cross/
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from dtradar_data.core.errors import InUseError
from dtradar_data.core.folder_lock import sole_writer

RUNS = Path("runs")


def run_dir(*parts: str) -> Path:
    """``runs/<part>/<part>/...`` (relative to the working directory, as every job's ``--out`` default)."""
    return RUNS.joinpath(*parts)


def dqn_checkpoint(scene: str) -> Path:
    """The ``model.pt`` that ``make train SCENE=<scene>`` writes and ``make eval``/``adapt``/``logged`` read."""
    return run_dir(scene, "dqn", "model.pt")


def agent_path(scene: str) -> Path:
    """The ``agent.json`` that ``make train SCENE=<scene>`` writes (the default agent) and ``make eval`` reads."""
    return run_dir(scene, "agent", "agent.json")


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


@contextmanager
def held_out_folder(out: str | Path, doing: str, *, what: str, option: str = "--out") -> Iterator[Path]:
    """The ``--out`` folder of a job, held by this process while the block runs (made if missing, removed again when
    the block fails and left it empty: :func:`no_empty_folder_on_failure`). A second job into the same folder, in
    this process or another, is refused at once (:class:`~dtradar_data.core.errors.InUseError`) naming the holder's
    pid and the folder, before it reads or writes anything there: two jobs (``what``: ``run``, ``benchmark``)
    writing one folder would interleave their files. A killed holder's lock is freed by the system (see
    :func:`dtradar_data.core.folder_lock.sole_writer`)."""
    out = Path(out)

    def refused(holder: str, busy: str) -> InUseError:
        return InUseError(
            f"{option} {out} is in use by {holder}, which is {busy or 'writing there'}: a second {what} into the same "
            f"folder would interleave its files with that one's",
            hint=f"wait until that one ends (or stop it), or pick another {option}",
        )

    with no_empty_folder_on_failure(out), sole_writer(out, doing, refused):
        yield out
