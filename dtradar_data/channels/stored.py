"""The per-path quantities a channel needs, read from a dataset's per-path table (``paths.parquet``).

:class:`StoredPaths` holds, for every path of the chosen cells, its baseband transfer matrix between isotropic V/H
ports, its delay and its four angles, with the cell each belongs to; :mod:`.generator` turns them into channels. A
version built without ``--rt.path-channels`` has no transfer matrices: asking it for channels raises
:class:`~dtradar_data.core.errors.MissingChannelDataError`, which says to rebuild (its port-reduced ``a_re``/``a_im``
fix one array pair, and no other array's channel follows from them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from dtradar_data.core.errors import InvalidSettingError, MissingChannelDataError
from dtradar_data.core.schema import CHANNEL_PATH_COLUMNS

_ANGLES = ("aod_zen_rad", "aod_az_rad", "aoa_zen_rad", "aoa_az_rad")


@dataclass(frozen=True)
class StoredPaths:
    """Paths of ``C`` cells, cell by cell: ``ix``, ``iy`` ``[C]``; per path ``cell`` (index into them, ascending),
    ``transfer`` ``complex128 [M, 2, 2]`` (receive V/H × transmit V/H, baseband), ``tau_s`` ``[M]`` and the angles
    ``theta_t``, ``phi_t``, ``theta_r``, ``phi_r`` ``[M]`` (rad)."""

    ix: np.ndarray
    iy: np.ndarray
    cell: np.ndarray
    transfer: np.ndarray
    tau_s: np.ndarray
    theta_t: np.ndarray
    phi_t: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray

    @property
    def num_cells(self) -> int:
        return len(self.ix)

    @property
    def counts(self) -> np.ndarray:
        """Paths per cell, ``int64 [C]``."""
        return np.bincount(self.cell, minlength=self.num_cells)

    @classmethod
    def from_table(cls, paths: pa.Table, cells: np.ndarray, *, name: str = "this dataset", tx: int = 0) -> StoredPaths:
        """The paths of ``cells`` (``int [C, 2]`` of ``(ix, iy)``, in the order wanted) from a per-path table
        (transmitter ``tx`` of a twin with several)."""
        missing = [c for c in CHANNEL_PATH_COLUMNS if c not in paths.column_names]
        if missing:
            scene, _, variant = name.partition("@")[0].partition("/")
            build = f"--scene {scene} --variant {variant}" if variant else "--scene <scene>"
            raise MissingChannelDataError(
                f"{name} stores no per-path transfer matrices (its paths.parquet lacks {', '.join(missing[:2])}, ...): "
                "it was built before they existed or without --rt.path-channels, and its port-reduced a_re/a_im give "
                "the channel of its own array pair only",
                hint=f"rebuild it with the channel columns: `python -m dtradar_data build {build} --rt.path-channels` "
                "(a new version, with the same settings otherwise; the old one stays loadable)",
            )
        cells = np.asarray(cells, np.int64).reshape(-1, 2)
        if "tx" in paths.column_names:
            paths = paths.filter(pc.equal(paths.column("tx"), tx))
        elif tx != 0:
            raise InvalidSettingError(f"{name} has one transmitter, not transmitter {tx}", hint="use tx=0")
        width = int(max(cells[:, 0].max(initial=0), pc.max(paths.column("ix")).as_py() or 0)) + 1
        key = paths.column("iy").to_numpy().astype(np.int64) * width + paths.column("ix").to_numpy()
        want = cells[:, 1] * width + cells[:, 0]
        order = np.argsort(want, kind="stable")
        pos = np.searchsorted(want[order], key)
        hit = (pos < len(want)) & (want[order][np.minimum(pos, len(want) - 1)] == key)
        rows = np.flatnonzero(hit)
        cell = order[pos[rows]]
        # rows of a cell stay in the table's order (strongest first); cells in the order asked
        sort = np.argsort(cell, kind="stable")
        rows, cell = rows[sort], cell[sort]

        def col(name: str) -> np.ndarray:
            return paths.column(name).to_numpy()[rows].astype(np.float64)

        t = np.empty((len(rows), 2, 2), np.complex128)
        for i, r in enumerate("vh"):
            for j, s in enumerate("vh"):
                t[:, i, j] = col(f"pol_{r}{s}_re") + 1j * col(f"pol_{r}{s}_im")
        theta_t, phi_t, theta_r, phi_r = (col(c) for c in _ANGLES)
        return cls(cells[:, 0], cells[:, 1], cell, t, col("tau_s"), theta_t, phi_t, theta_r, phi_r)
