"""Staging folders held by a live process, and the cleanup of those a killed one left behind.

A writer stages a version in ``<parent>/<prefix><random>/`` and renames it into place when it is complete; a process
killed with SIGKILL (or by the OOM killer, or a power cut) leaves that folder behind. Each stage is *held*: an
exclusive OS file lock on ``<parent>/<prefix><random>.lock``, taken before the folder is created and released by the
kernel when its process ends, however it ends. :func:`clean_stale_stages` removes the folders whose lock it can take
(their writer is gone) and leaves those whose lock is held (a live writer, in this process or another): no clock, no
guess from a pid that may have been reused. A folder of the prefix without a lock file was left by a dtradar before
this one, and is removed when it looks like such a stage (the caller says what that looks like). Locks that a second
process waits on, saying for whom, are :func:`dtradar_data.core.files.waiting_lock`.

The same helpers serve the RT store (``<root>/work/stage-*`` of a version written, ``<root>/work/pull-*`` of a
download: :mod:`dtradar_data.store.writing`), the logged store (``<root>/work/logged-*``, ``<root>/work/pull-logged-*``)
and the Minari copies of :mod:`dtradar_rl.offline.minari_copy` (hidden ``.dtradar-stage-*`` folders in the Minari data
path). A writer whose prefix names what it writes (``stage-<scene>-<variant>-<version>-``) holds its stage under that
prefix, and the cleaner of every such stage takes the common prefix and the pattern of the rest (``infix``).
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from filelock import FileLock, Timeout

__all__ = ["LOCK_SUFFIX", "clean_stale_stages", "held_stage"]

LOCK_SUFFIX = ".lock"
#: A lock file without its folder is only removed once it is this old: a writer creates (and then locks) its lock
#: file a moment before its folder, and that moment must not look like debris.
ORPHAN_LOCK_AGE_S = 60.0


def _take(lock_path: Path) -> FileLock | None:
    """The lock at ``lock_path`` if nobody holds it (its writer is gone), else None."""
    lock = FileLock(lock_path)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        return None
    except OSError:  # unreadable or vanished meanwhile: not ours to judge now
        return None
    return lock


def clean_stale_stages(
    parent: Path, prefix: str, *, infix: str = "", lockless: Callable[[Path], bool] | None = None
) -> list[Path]:
    """Remove the stage folders ``<parent>/<prefix><infix><random>`` that no live process holds; returns those removed.

    Only names of exactly that shape (``infix`` a regular expression, then ``tempfile``'s 8 characters) are
    considered, so another writer's folder that merely starts with the prefix (a ray-tracing build's ``work/<scene>``
    for a scene named ``logged-...``) is never touched. A folder with its lock file beside it is removed when the
    lock can be taken; one without (left by a dtradar before held stages, which had none) only when
    ``lockless(folder)`` says it looks like a stage of this kind."""
    if not parent.is_dir():
        return []
    shape = re.compile(re.escape(prefix) + infix + r"[a-z0-9_]{8}")
    removed = []
    for stage in sorted(parent.glob(f"{prefix}*")):
        if not shape.fullmatch(stage.name) or not stage.is_dir() or stage.is_symlink():
            continue
        lock_path = stage.with_name(stage.name + LOCK_SUFFIX)
        if not lock_path.exists() and not (lockless is not None and lockless(stage)):
            continue
        lock = _take(lock_path)
        if lock is None:
            continue  # a live writer's
        try:
            shutil.rmtree(stage, ignore_errors=True)
            removed.append(stage)
            lock_path.unlink(missing_ok=True)
        finally:
            lock.release()
    now = time.time()
    for lock_path in sorted(parent.glob(f"{prefix}*{LOCK_SUFFIX}")):  # killed between its folder's end and its own
        stage = lock_path.with_name(lock_path.name[: -len(LOCK_SUFFIX)])
        if not shape.fullmatch(stage.name):
            continue
        try:
            if stage.exists() or now - lock_path.stat().st_mtime < ORPHAN_LOCK_AGE_S:
                continue
        except OSError:
            continue
        lock = _take(lock_path)
        if lock is not None:
            try:
                lock_path.unlink(missing_ok=True)
            finally:
                lock.release()
    return removed


@contextmanager
def held_stage(parent: Path, prefix: str, *, lockless: Callable[[Path], bool] | None = None) -> Iterator[Path]:
    """A new empty folder ``<parent>/<prefix><random>``, held for the block (see the module docstring). Rename it
    into place inside the block; whatever is left of it at the end is removed. Stale stages of the prefix are
    cleaned first (:func:`clean_stale_stages`, with ``lockless``)."""
    parent.mkdir(parents=True, exist_ok=True)
    clean_stale_stages(parent, prefix, lockless=lockless)
    fd, name = tempfile.mkstemp(prefix=prefix, suffix=LOCK_SUFFIX, dir=parent)
    os.close(fd)
    lock_path = Path(name)
    lock = FileLock(lock_path)
    lock.acquire()  # fresh and unique: free at once (a cleaner leaves lock files this young alone)
    stage = lock_path.with_name(lock_path.name[: -len(LOCK_SUFFIX)])
    try:
        stage.mkdir()
        yield stage
    finally:
        try:
            shutil.rmtree(stage, ignore_errors=True)  # renamed into place already when all went well
            lock_path.unlink(missing_ok=True)
        finally:
            lock.release()
