"""One loaded logged version (:class:`LoggedDataset`: the transition table and its ``meta.json``), its Minari id and
where its Minari copy goes.

The Minari copy of a data root's logged version is a Minari dataset in :func:`minari_root`: Minari's own setting
``MINARI_DATASETS_PATH`` when it is set, else ``<data root>/minari``, one Minari folder per data root (not Minari's
default ``~/.minari/datasets``, which every data root would share: the same id ``dtradar/...-v0`` names the first
version logged in *each* data root, so two roots would write different data under one id). Load it with
``MINARI_DATASETS_PATH=<data root>/minari`` set, or with :func:`dtradar_rl.offline.minari_copy.load_minari`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from dtradar_data.core import layout as P
from dtradar_data.core.ids import LoggedId, is_tag, parse_logged_id
from dtradar_data.store.logged.table import arrays

__all__ = ["MINARI_DIR", "MINARI_ENV", "LoggedDataset", "minari_id", "minari_root"]

#: Minari's own setting: the folder of its local datasets.
MINARI_ENV = "MINARI_DATASETS_PATH"
#: The folder under the data root holding the Minari copies when ``MINARI_DATASETS_PATH`` is not set.
MINARI_DIR = "minari"


def minari_root() -> Path:
    """Where the Minari copies of logged datasets are written and read: ``$MINARI_DATASETS_PATH`` if set, else
    ``<data root>/minari`` (one Minari folder per data root; see the module docstring). Absolute."""
    value = os.environ.get(MINARI_ENV, "").strip()
    return (Path(value).expanduser() if value else P.data_root() / MINARI_DIR).absolute()


def minari_id(lid: LoggedId, tag: str | None) -> str:
    """The Minari id of a logged version: ``dtradar/<scene>-<variant>-<behaviour>-v<N>`` (``N`` from tag ``vN``)."""
    n = int(tag[1:]) if tag and is_tag(tag) else 0
    return f"dtradar/{lid.scene}-{lid.variant}-{lid.behaviour}-v{n}"


@dataclass
class LoggedDataset:
    """One loaded logged version: the transition table and its metadata (``meta.json``)."""

    name: str
    version: str
    tag: str | None
    table: pa.Table
    meta: dict[str, Any]
    path: Path

    def __len__(self) -> int:
        return self.table.num_rows

    @property
    def frame(self):
        """The table as a polars DataFrame."""
        import polars as pl

        return pl.from_arrow(self.table)

    @property
    def id(self) -> LoggedId:
        return parse_logged_id(self.name).with_revision(self.tag or self.version)

    @property
    def minari_id(self) -> str:
        return minari_id(parse_logged_id(self.name), self.tag)

    @property
    def minari_path(self) -> Path:
        """The folder of its Minari copy (which may not be written yet): ``minari_root() / minari_id``."""
        return minari_root() / self.minari_id

    def arrays(self) -> dict[str, np.ndarray]:
        return arrays(self.table)

    def __repr__(self) -> str:
        s = self.meta.get("stats") or {}
        return (
            f"LoggedDataset({self.name!r}, version={self.version!r}, tag={self.tag!r}, steps={len(self)}, "
            f"episodes={s.get('episodes')}, parent={self.meta.get('parent')!r})"
        )
