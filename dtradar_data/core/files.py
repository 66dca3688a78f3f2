"""Small file helpers shared by every layer: atomic text writes, file hashes, JSON-safe values, and file locks whose
waits say what they wait for (:func:`waiting_lock`)."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import math
import os
import random
import re
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, Any

import numpy as np
from filelock import FileLock, Timeout

from dtradar_data.core.errors import MissingDependencyError

LOCK_NOTICE_EVERY_S = 60.0
"""While a lock is held by another process, a waiting one says so again this often (with the holder's progress)."""


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def json_safe(obj: Any) -> Any:
    # Stats of an all-null column come out as NaN; strict JSON (and the YAML card) has no NaN, so store null.
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        return json_safe(obj.item())
    if isinstance(obj, Path):
        return str(obj)
    return obj


@contextlib.contextmanager
def open_atomic(path: Path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """A new file that replaces ``path`` only when the block ends without an error (a temp file in the same
    directory, fsynced, then ``os.replace``): readers and a killed writer leave the old file or the new, never half.
    ``mode`` is ``"w"`` or ``"wb"`` (``"w+b"`` for writers that seek back); ``kwargs`` go to :func:`open`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _new_temp(path)
    try:
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


#: What follows ``.<name>`` in a temp file of :func:`open_atomic`: a dot, 8 characters of :data:`_TEMP_CHARS`, ``.tmp``.
_TEMP_TAIL = r"\.[a-z0-9_]{8}\.tmp"
_TEMP_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_"  # tempfile's own, so older writers' temp files still match


def _new_temp(path: Path) -> tuple[int, str]:
    """``(fd, name)`` of a new temp file ``.<name>.<8 random>.tmp`` beside ``path``, created with mode 0666 less the
    umask, as :func:`open` creates a file (0644 under umask 022). Not :func:`tempfile.mkstemp`: its 0600 would stay on
    the file renamed into place, and a shared mirror's files would be unreadable to everyone but their writer."""
    rng = random.SystemRandom()
    for _ in range(tempfile.TMP_MAX):
        name = str(path.parent / f".{path.name}.{''.join(rng.choices(_TEMP_CHARS, k=8))}.tmp")
        try:
            return os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666), name
        except FileExistsError:
            continue
    raise FileExistsError(errno.EEXIST, f"no free temp file name beside {path}")


def temp_siblings(path: Path) -> list[Path]:
    """The temp files that :func:`open_atomic` writers of ``path`` made beside it, of live writers or of killed ones
    (a ``kill -9`` mid-write leaves its temp file behind): only a caller that holds the lock every writer of ``path``
    holds while it writes may remove them, and they are then a killed writer's."""
    path = Path(path)
    shape = re.compile(re.escape(f".{path.name}") + _TEMP_TAIL)
    try:
        names = [p for p in path.parent.iterdir() if shape.fullmatch(p.name)]
    except OSError:  # no folder (nothing written yet), or unreadable
        return []
    return sorted(p for p in names if p.is_file() and not p.is_symlink())


def write_atomic(path: Path, data: str | bytes) -> None:
    """Write ``data`` (text or bytes) through :func:`open_atomic`."""
    with open_atomic(path, "wb" if isinstance(data, bytes) else "w") as f:
        f.write(data)


def human_size(n: int | None) -> str:
    """``1536`` -> ``'1.5 KiB'``; ``None`` -> ``'-'``."""
    if n is None:
        return "-"
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{int(size)} B" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size:.1f} GiB"


def installed_file(dist: str, rel: str, what: str) -> Path:
    """A file shipped inside an installed distribution (``rel`` from its site-packages root), found through package
    metadata so nothing is imported; :class:`MissingDependencyError` says how to install or repair it."""
    from importlib import metadata

    try:
        path = Path(str(metadata.distribution(dist).locate_file(rel)))
    except metadata.PackageNotFoundError as e:
        raise MissingDependencyError(
            f"{what} comes with {dist}, which is not installed", hint="run `make setup`"
        ) from e
    if not path.is_file():
        raise MissingDependencyError(
            f"{path} is missing from the installed {dist}", hint=f"reinstall it: `pip install --force-reinstall {dist}`"
        )
    return path


def holder_path(lock: Path) -> Path:
    """The file beside a lock that says who holds it (pid, host, since when, doing what) while it is held."""
    return lock.with_name(lock.name + ".holder")


def read_holder(lock: Path) -> dict[str, Any]:
    """What the holder of ``lock`` wrote about itself; empty when unknown (an older version of dtradar, or gone)."""
    try:
        info = json.loads(holder_path(lock).read_text())
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def live_holder(lock: Path) -> dict[str, Any] | None:
    """What the live holder of the :func:`waiting_lock` ``lock`` says about itself, or None when no live process
    holds it. Asked only where a holder file is present (a holder writes it once it has the lock, and removes it
    before it lets go; a killed one leaves it behind): the question is a shared lock taken and dropped at once, which
    would make a process taking the lock at that very moment wait for it, and say so."""
    if not holder_path(lock).is_file():
        return None
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return read_holder(lock)
        fcntl.flock(fd, fcntl.LOCK_UN)  # free: the holder file is a killed holder's
        return None
    finally:
        os.close(fd)


def describe_holder(info: dict[str, Any]) -> str:
    """``pid 123 (on host h, since 10:02:03 UTC)``, or ``another process`` when nothing is known."""
    if not isinstance(info.get("pid"), int):
        return "another process"
    extra = []
    if info.get("host") and info["host"] != socket.gethostname():
        extra.append(f"on host {info['host']}")
    if info.get("since"):
        extra.append(f"since {str(info['since'])[11:19]} UTC")
    return f"pid {info['pid']}" + (f" ({', '.join(extra)})" if extra else "")


@contextlib.contextmanager
def waiting_lock(
    lock: Path,
    doing: str,
    *,
    then: str = "",
    progress: Callable[[], str] | None = None,
    notice_after_s: float = 0.0,
    every_s: float | None = None,
) -> Iterator[None]:
    """Hold the exclusive file lock ``lock`` for the block (``doing`` says for what, e.g. ``building x version v``).

    A wait is never silent: when another process holds the lock for longer than ``notice_after_s``, one line on
    stderr names the holder (its pid, from :func:`holder_path`), what it is doing, what happens ``then``, and that
    Ctrl-C is safe; every ``every_s`` (default :data:`LOCK_NOTICE_EVERY_S`) another line says how long it has waited
    and the holder's ``progress()``. The wait itself ends when the holder does (a killed holder's lock is released
    by the system)."""
    lock = Path(lock)
    lock.parent.mkdir(parents=True, exist_ok=True)
    file_lock = FileLock(str(lock))
    every = LOCK_NOTICE_EVERY_S if every_s is None else every_s
    try:
        file_lock.acquire(timeout=notice_after_s)
    except Timeout:
        start = time.monotonic()
        holder = describe_holder(read_holder(lock))
        busy = read_holder(lock).get("doing") or doing
        print(
            f"waiting for {holder}, which is {busy}{'; then ' + then if then else ''}. "
            f"Ctrl-C is safe: it stops this process only, stored datasets stay as they are (lock: {lock})",
            file=sys.stderr,
            flush=True,
        )
        while True:
            try:
                file_lock.acquire(timeout=every)
                break
            except Timeout:
                waited = time.monotonic() - start
                status = progress() if progress is not None else ""
                print(
                    f"still waiting for {describe_holder(read_holder(lock))} after {_duration(waited)}"
                    + (f": {status}" if status else ""),
                    file=sys.stderr,
                    flush=True,
                )
        print(f"the lock is free after {_duration(time.monotonic() - start)}; going on", file=sys.stderr, flush=True)
    info = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "since": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "doing": doing,
    }
    try:
        try:
            write_atomic(holder_path(lock), json.dumps(info) + "\n")
        except OSError:
            pass  # only a waiting process's message loses the holder's pid
        yield
    finally:
        if read_holder(lock).get("pid") == os.getpid():
            holder_path(lock).unlink(missing_ok=True)
        file_lock.release()


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"
