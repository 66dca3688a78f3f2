"""A loaded dataset: one version of one ``scene/variant`` per-cell table, plus its metadata.

The object is a read-only view; building and storing live in :mod:`dtradar_data.pipeline` and
:mod:`dtradar_data.store`. ``Dataset.from_table`` wraps an in-memory table (tests, synthetic data) the same way.

Moving twins
------------
A *moving* twin holds ``T`` snapshots of the world in one per-cell table: an int32 column ``t`` (snapshot index
``0 .. T-1``), every snapshot with all ``H x W`` cells, rows sorted by ``(t, iy, ix)``; ``blocked`` at snapshot ``t``
is a static obstacle or a mover occupying the cell then; a bool column ``mover`` marks the latter (a subset of
``blocked``; radio features are null there like on any blocked cell); ``meta["moving"] = {"snapshots": T, "dt_s":
seconds between snapshots, "movers": [names]}``. Snapshot ``k`` is the world at time ``k * dt_s``, and the world is
periodic (after ``T-1`` comes ``0``). :attr:`Dataset.snapshots` is ``T`` (1 for a static twin) and
:meth:`Dataset.snapshot` is one snapshot as a static twin; ``blocked`` and ``grid`` of a moving twin refuse, as
they have one grid per snapshot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pyarrow as pa

from dtradar_data.core.errors import (
    CorruptDatasetError,
    InvalidCoordinatesError,
    MissingSceneError,
    SchemaMismatchError,
)
from dtradar_data.core.files import sha256_file
from dtradar_data.core.grid import Grid
from dtradar_data.core.layout import SCENE_XML, is_scene_file
from dtradar_data.core.schema import RADIO_COLUMNS, tx_column

#: The grid of a stored dataset is the scene's receiver grid (``meta["grid"]``); one class for both.
GridInfo = Grid


@dataclass(frozen=True)
class Dataset:
    """One dataset version. ``table`` rows are in row-major order (``iy`` outer, ``ix`` inner)."""

    name: str
    table: pa.Table
    meta: dict[str, Any]
    version: str | None = None
    path: Path | None = None
    paths_table: pa.Table | None = field(default=None, repr=False)

    @classmethod
    def from_table(cls, table: pa.Table, meta: dict[str, Any], name: str = "memory/synthetic") -> Dataset:
        keys = [("iy", "ascending"), ("ix", "ascending")]
        if "t" in table.column_names:  # a moving twin: snapshot by snapshot
            keys.insert(0, ("t", "ascending"))
        table = table.sort_by(keys)
        return cls(name=name, table=table, meta=meta, version=meta.get("version"))

    @property
    def frame(self) -> pl.DataFrame:
        """The per-cell table as a polars DataFrame (zero-copy from Arrow where possible)."""
        return pl.from_arrow(self.table)

    @property
    def grid_info(self) -> GridInfo:
        return GridInfo.from_meta(self.meta["grid"])

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid_info.shape

    @property
    def transmitters(self) -> int:
        """``K``, the twin's transmitters: 1, plus one per ``tx{k}_`` column set of the table (transmitter ``k``'s
        radio columns, :func:`~dtradar_data.core.schema.tx_column`)."""
        names, k = set(self.table.column_names), 1
        while tx_column("num_paths", k) in names:
            k += 1
        return k

    def heard(self) -> np.ndarray:
        """``bool[H, W]`` (static twins): the cell has a path from at least one transmitter."""
        self._static_only("reception mask")
        out = np.zeros(self.shape, bool)
        for k in range(self.transmitters):
            col = self.table.column(tx_column("num_paths", k)).to_numpy(zero_copy_only=False)
            out |= col.reshape(self.shape) > 0
        return out

    # -- moving twins (see the module docstring) ------------------------------------------------------------------
    @property
    def is_moving(self) -> bool:
        """Whether the table holds snapshots in time (a ``t`` column, or ``meta["moving"]``)."""
        return "t" in self.table.column_names or "moving" in self.meta

    @property
    def snapshots(self) -> int:
        """``T``, the snapshots of a moving twin; 1 for a static one. A moving table whose ``t`` column, metadata and
        row count disagree is a :class:`SchemaMismatchError`."""
        if not self.is_moving:
            return 1
        moving = self.meta.get("moving")
        if "t" not in self.table.column_names or not isinstance(moving, dict) or "snapshots" not in moving:
            raise SchemaMismatchError(
                f"{self.name}: a moving twin needs both a 't' column and meta['moving']['snapshots']",
                hint="write both (see dtradar_data.core.dataset), or neither for a static twin",
            )
        t = int(moving["snapshots"])
        h, w = self.shape
        if t < 1 or self.table.num_rows != t * h * w:
            raise SchemaMismatchError(
                f"{self.name}: {self.table.num_rows} rows for {t} snapshots of {w} x {h} cells",
                hint="a moving twin holds every cell of every snapshot, rows sorted by (t, iy, ix)",
            )
        return t

    def snapshot(self, k: int) -> Dataset:
        """Snapshot ``k`` of a moving twin as a static twin (the same name and version; no ``t`` column;
        ``meta["snapshot"] = {"t": k, "time_s": k * dt_s}``). A static twin is its own snapshot 0."""
        n_snap = self.snapshots
        if not self.is_moving and k == 0:
            return self
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < n_snap:
            raise InvalidCoordinatesError(
                f"{self.name}: snapshot {k!r} is not one of 0..{n_snap - 1}", hint="pass an int index"
            )
        h, w = self.shape
        part = self.table.slice(int(k) * h * w, h * w)
        t = part.column("t").to_numpy(zero_copy_only=False)
        if not (t == k).all():
            raise SchemaMismatchError(
                f"{self.name}: rows {int(k) * h * w}..{(int(k) + 1) * h * w - 1} are not all snapshot {k}",
                hint="sort a moving twin's rows by (t, iy, ix) (Dataset.from_table does)",
            )
        dt_s = float(self.meta["moving"].get("dt_s", 0.0))
        meta = {key: v for key, v in self.meta.items() if key != "moving"}
        meta["snapshot"] = {"t": int(k), "time_s": int(k) * dt_s}
        return Dataset(self.name, part.drop_columns(["t"]), meta, self.version, self.path)

    def _static_only(self, what: str) -> None:
        if self.is_moving:
            raise SchemaMismatchError(
                f"{self.name} is a moving twin of {self.snapshots} snapshots: its {what} has one grid per snapshot",
                hint="read one snapshot with ds.snapshot(k) (dtradar_rl.task.grid_mdp.MovingGridMDP reads them all)",
            )

    @property
    def blocked(self) -> np.ndarray:
        """``bool[H, W]``: True where an obstacle occupies the cell (static twins; see :meth:`snapshot`)."""
        if self.is_moving:
            self._static_only("blocked mask")
        return self.table.column("blocked").to_numpy(zero_copy_only=False).reshape(self.shape)

    def grid(self, columns: tuple[str, ...] | list[str] = RADIO_COLUMNS, fill: float = np.nan) -> np.ndarray:
        """``float32[H, W, F]`` of the given columns; nulls (no path, blocked) become ``fill`` (static twins; see
        :meth:`snapshot`)."""
        if self.is_moving:
            self._static_only("feature grid")
        h, w = self.shape
        out = np.empty((h, w, len(columns)), dtype=np.float32)
        for k, name in enumerate(columns):
            col = self.table.column(name).cast(pa.float32()).fill_null(fill)
            out[..., k] = col.to_numpy(zero_copy_only=False).reshape(h, w)
        return out

    @property
    def scene_xml(self) -> Path:
        """The Mitsuba XML of the scene this version was traced from, stored in it with its meshes
        (``<version>/scene/scene.xml``): ``sionna.rt.load_scene(str(ds.scene_xml))`` opens it. Its files are checked
        against the sha256 ``meta.json`` records (:class:`CorruptDatasetError`); a version that stores no scene
        raises :class:`MissingSceneError`, which says how to get one."""
        files = self.meta.get("files") or {}
        if self.path is None or SCENE_XML not in files:
            raise self._no_scene()
        for name, rec in sorted(files.items()):
            if is_scene_file(name) and not (
                (self.path / name).is_file() and sha256_file(self.path / name) == rec.get("sha256")
            ):
                raise CorruptDatasetError(
                    f"{self.path / name} is missing or does not match the sha256 recorded in meta.json",
                    hint=f"`python -m dtradar_data verify {self.name}` lists every problem; re-pull or rebuild it",
                )
        return self.path / SCENE_XML

    def _no_scene(self) -> MissingSceneError:
        if self.path is None:
            return MissingSceneError(
                f"{self.name} is a table in memory: it has no stored scene", hint="load a stored version"
            )
        if self.is_moving:
            return MissingSceneError(
                f"{self.name} is a moving twin: its world changes every snapshot, and it stores no scene",
                hint=f"open the scene of its static twin, {self.meta.get('scene')}/blueprint",
            )
        build = f"python -m dtradar_data build --scene {self.meta.get('scene')} --variant {self.meta.get('variant')}"
        return MissingSceneError(
            f"{self.name}@{self.version} stores no scene (no {SCENE_XML} in {self.path}): it was built before "
            "versions carried the scene they were traced from",
            hint=f"build it again: remove the version (`rm -r {self.path}`), then `{build}` with the flags it was "
            "built with; the same version comes back, now with its scene (the scene files do not enter the version "
            "hash), and its tag stays",
        )

    def __repr__(self) -> str:
        h, w = self.shape
        return f"Dataset({self.name!r}, version={self.version!r}, grid={w}x{h}, rows={self.table.num_rows})"
