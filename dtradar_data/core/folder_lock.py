"""One writer per output folder: :func:`sole_writer` holds an OS file lock on a folder for as long as a job writes it,
and a second job that would write the same folder is refused at once, told which process holds it.

Two ``make train`` runs (or two offline benchmarks) into one folder would otherwise interleave their checkpoints,
curves and results, each overwriting the other's files with its own, and neither would notice. The lock is
``fcntl.flock`` on a lock file inside the folder, so the kernel releases it when its process ends, however it ends
(``kill -9``, the OOM killer): no pid to judge, no clock. While held, the lock file says who holds it (pid, host,
since when, doing what), which is what a refused job prints; on the way out the holder removes it, so a finished,
failed or refused job leaves the folder's files as they were. A killed holder leaves it behind with its stale
description, and the next job takes the free lock and writes its own.

A waiting lock (one that says whom it waits for, then goes on) is :func:`dtradar_data.core.files.waiting_lock`: right
for a store write that takes a moment, not for a training of hours whose results the second one would replace.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import describe_holder

__all__ = ["LOCK_FILE", "sole_writer"]

#: The lock file inside a held folder (hidden: listings of a run's files skip it, and it is gone once the job ends).
LOCK_FILE = ".dtradar-writer.lock"

#: ``refused(holder, doing)`` -> the error to raise: ``holder`` is ``pid 123 (since 10:02:03 UTC)`` or ``another
#: process``, ``doing`` what the holder said it does (empty when it did not say).
Refusal = Callable[[str, str], DtradarError]


@contextmanager
def sole_writer(folder: str | Path, doing: str, refused: Refusal) -> Iterator[Path]:
    """Hold ``folder`` (made if missing) for this process while the block runs; ``doing`` says what for (``training
    cubicle/blueprint``). When another live process holds it, raise ``refused(holder, its doing)`` before anything is
    written. The lock is released, and its file removed, when the block ends."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / LOCK_FILE
    fd = _take(lock)
    if fd is None:
        info = _read_info(lock)
        raise refused(describe_holder(info), str(info.get("doing") or ""))
    try:
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "since": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "doing": doing,
        }
        os.ftruncate(fd, 0)  # a killed holder's description may still be in it
        os.pwrite(fd, (json.dumps(info) + "\n").encode(), 0)
        yield folder
    finally:
        # Removed while still held: a process that opened it meanwhile finds, once it has the lock, that the folder's
        # lock file is no longer the one it locked, and takes the new one (_take).
        lock.unlink(missing_ok=True)
        os.close(fd)


def _take(lock: Path) -> int | None:
    """A descriptor of ``lock`` holding its exclusive lock, or None when a live process holds it."""
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        except BaseException:
            os.close(fd)
            raise
        try:
            current = os.stat(lock).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(fd).st_ino:
            return fd
        os.close(fd)  # its holder ended and removed it after we opened it: lock the file the folder has now


def _read_info(lock: Path) -> dict[str, Any]:
    try:
        info = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}
