"""One trace batch: receivers in, per-cell features (and per-path rows) out; saved to and read from the work folder.

The unit of resumable work: ``batch_<b>.npz`` files in a build's work folder are finished batches. Every executor
(serial in :mod:`dtradar_data.pipeline.builder`, Ray in :mod:`dtradar_data.pipeline.executors`) traces with
:func:`trace_batch` and stores with :func:`save_batch`, so their results are the same bytes.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from dtradar_data.rt import features


def batch_path(work_dir: Path, b: int) -> Path:
    return work_dir / f"batch_{b:05d}.npz"


def trace_batch(
    tracer, points: np.ndarray, ix: np.ndarray, iy: np.ndarray, *, per_path: bool
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Trace ``points`` (receivers of the cells ``ix``, ``iy``) and reduce them to ``(cells, paths)`` arrays."""
    batch = tracer.trace(points)
    cells = features.reduce_cells(batch)
    paths = features.path_rows(batch, ix, iy) if per_path else {}
    return cells, paths


def save_batch(path: Path, cells: dict[str, np.ndarray], paths: dict[str, np.ndarray]) -> None:
    """Write a finished batch through a temporary file and a rename: a batch file is whole or absent."""
    buf = io.BytesIO()
    np.savez(buf, **{f"c_{k}": v for k, v in cells.items()}, **{f"p_{k}": v for k, v in paths.items()})
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)


def load_batch(path: Path) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    with np.load(path, allow_pickle=True) as z:
        cells = {k[2:]: z[k] for k in z.files if k.startswith("c_")}
        paths = {k[2:]: z[k] for k in z.files if k.startswith("p_")}
    return cells, paths
