"""What a process keeps of a logged dataset between runs (its relabeller, its memory windows, its d3rlpy dataset),
checked for content as the solve cache on disk is (:mod:`dtradar_rl.tabular.cache`).

The benchmark trains many agents on each log, so each of these is built once and kept (:class:`LogCache`, the few
most recent). An entry is found by where its log is from (folder, name, version) but served only when it was built
from the same content: the sha256 of the transition table it was built from is recorded with it and compared with
the table asked for (:func:`table_content`). The folder and version alone do not say that: a version is a hash of the
*logging inputs*, so a log removed and logged again under them (on a GPU, whose sums need not repeat bit for bit) or
put back from another copy is another table under the same key, and a kept relabeller or memory window of the old
one would train every later agent on rows that are not the log's. A mismatch builds it again and says so.
"""

from __future__ import annotations

import hashlib
import sys
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

import numpy as np
import pyarrow as pa

from dtradar_data.store.logged import LoggedDataset, table_digest

__all__ = ["LogCache", "log_content", "table_content"]

T = TypeVar("T")

#: ``id(table) -> (weak reference, digest)``: an Arrow table is immutable, so the same object has the same content
#: and is hashed once (0.1 s per 100 K rows), however many agents are trained on it.
_DIGESTS: dict[int, tuple[weakref.ref, str]] = {}


def table_content(table: pa.Table) -> str:
    """The sha256 of a table's content (:func:`~dtradar_data.store.logged.table_digest`), once per object."""
    key = id(table)
    hit = _DIGESTS.get(key)
    if hit is not None and hit[0]() is table:
        return hit[1]
    digest = table_digest(table)

    def forget(ref: weakref.ref, key: int = key) -> None:
        if _DIGESTS.get(key, (None,))[0] is ref:  # not a newer table's that took the freed id meanwhile
            del _DIGESTS[key]

    _DIGESTS[key] = (weakref.ref(table, forget), digest)
    return digest


def log_content(logged: LoggedDataset, *more: np.ndarray | str) -> str:
    """The content a kept entry of ``logged`` is checked against: its table's sha256, and ``more`` (arrays or
    strings of what else the entry was built from, e.g. the twin's moves for memory windows)."""
    if not more:
        return table_content(logged.table)
    h = hashlib.sha256(table_content(logged.table).encode())
    for part in more:
        h.update(part.encode() if isinstance(part, str) else np.ascontiguousarray(part).tobytes())
    return "sha256:" + h.hexdigest()[:16]


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class LogCache(Generic[T]):
    """The ``size`` most recent ``what`` (e.g. ``"relabeller"``) of logs in this process, each with the content it
    was built from (module docstring)."""

    def __init__(self, what: str, size: int = 2):
        self.what, self.size = what, size
        self.entries: OrderedDict[Hashable, tuple[str, T]] = OrderedDict()

    def get(
        self,
        key: Hashable,
        content: str,
        build: Callable[[], T],
        *,
        where: str = "",
        say: Callable[[str], None] = _stderr,
    ) -> T:
        """The kept value of ``key`` when it was built from ``content``, else ``build()`` kept (and, for a kept one
        of other content, one line to ``say`` naming the log ``where`` is from)."""
        hit = self.entries.get(key)
        if hit is not None:
            self.entries.move_to_end(key)
            if hit[0] == content:
                return hit[1]
            say(
                f"the {self.what} kept in this process for {where or key} was built from other transitions "
                f"({hit[0]}, the log now holds {content}): building it again"
            )
        value = build()
        self.entries[key] = (content, value)
        self.entries.move_to_end(key)
        while len(self.entries) > self.size:
            self.entries.popitem(last=False)
        return value

    def clear(self) -> None:
        self.entries.clear()

    def __len__(self) -> int:
        return len(self.entries)
