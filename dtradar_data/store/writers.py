"""Which versions of a dataset a live process is writing right now, for the readers that would otherwise take an
unfinished version for a damaged one (``verify``).

A version is written in a staging folder and renamed into place whole (:mod:`dtradar_data.store.writing`,
:mod:`dtradar_data.store.logged`), so no reader ever sees half of its files. What a reader can see is a version
that is not there yet, or not yet again: a ray-tracing build runs for minutes to hours before its version appears
(``verify`` would call the dataset "not built"), and logging a damaged logged version again replaces that damaged
folder at the end (``verify`` would report it damaged while its replacement is under way). Both writers hold a lock
for the whole time, which says who holds it (:func:`~dtradar_data.core.files.waiting_lock`): the build lock
``<root>/work/<scene>/<variant>/<version>.lock`` (:mod:`dtradar_data.pipeline.storing`) and the logging lock
``.<version>.logging.lock`` beside the logged versions (:func:`~dtradar_data.store.logged.logging_lock`).
:func:`being_written` reads those; a lock whose process was killed is free, and its version is not being written.
A Hub pull's version is known only once its download is complete, and it is renamed into place within a second.
"""

from __future__ import annotations

from pathlib import Path

from dtradar_data.core import layout as P
from dtradar_data.core.errors import InUseError
from dtradar_data.core.files import describe_holder, live_holder
from dtradar_data.core.ids import HASH_RE, DatasetId, LoggedId, is_hash, is_logged_name, parse_logged_id
from dtradar_data.store.catalog import as_id
from dtradar_data.store.logged import logged_dir

__all__ = ["being_written", "check_not_being_written", "writer_locks"]

_LOGGING_LOCK = ".logging.lock"


def writer_locks(name: str | DatasetId | LoggedId) -> dict[str, Path]:
    """``{version: lock}`` of the locks a writer of a version of ``name`` holds while it writes it (held or not)."""
    if is_logged_name(name):
        lid = parse_logged_id(name).with_revision(None)
        folder = logged_dir(lid)
        locks = (
            {p.name[1 : -len(_LOGGING_LOCK)]: p for p in folder.glob(f".*{_LOGGING_LOCK}")} if folder.is_dir() else {}
        )
    else:
        did = as_id(name, check_known=False)
        folder = P.work_root_to_read() / did.scene / did.variant  # a reader's: a read-only root is fine
        locks = {p.stem: p for p in folder.glob("*.lock")} if folder.is_dir() else {}
    return {v: lock for v, lock in locks.items() if HASH_RE.fullmatch(v)}


def being_written(name: str | DatasetId | LoggedId) -> dict[str, str]:
    """``{version: who writes it and how}`` (``pid 123 (since 10:02:03 UTC), which is building ...``) of the versions
    of ``name`` that a live process is writing now."""
    out = {}
    for version, lock in sorted(writer_locks(name).items()):
        info = live_holder(lock)
        if info is not None:
            doing = info.get("doing")
            out[version] = describe_holder(info) + (f", which is {doing}" if doing else "")
    return out


def check_not_being_written(name: str | DatasetId | LoggedId, revision: str | None = None) -> None:
    """:class:`InUseError` when the version ``revision`` of ``name`` (a hash or a prefix of one; None: any version) is
    being written by a live process, naming it: a reader that found it missing or damaged has found it unfinished."""
    parsed = parse_logged_id(name) if is_logged_name(name) else as_id(name, check_known=False)
    shown, revision = parsed.name, revision or parsed.revision
    busy = {
        v: who
        for v, who in being_written(name).items()
        if revision is None or (is_hash(revision) and v.startswith(revision))
    }
    if not busy:
        return
    version, who = next(iter(busy.items()))
    raise InUseError(
        f"version {version} of {shown} is being written by {who}: it is unfinished, not damaged",
        hint=f"verify it once that process has finished (`python -m dtradar_data verify {shown}@{version[:12]}`)",
    )
