"""One loaded logged version (:class:`LoggedDataset`: the transition table and its ``meta.json``) and its Minari id."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from dtradar_data.core.ids import LoggedId, is_tag, parse_logged_id
from dtradar_data.store.logged.table import arrays

__all__ = ["LoggedDataset", "minari_id"]


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

    def arrays(self) -> dict[str, np.ndarray]:
        return arrays(self.table)

    def __repr__(self) -> str:
        s = self.meta.get("stats") or {}
        return (
            f"LoggedDataset({self.name!r}, version={self.version!r}, tag={self.tag!r}, steps={len(self)}, "
            f"episodes={s.get('episodes')}, parent={self.meta.get('parent')!r})"
        )
