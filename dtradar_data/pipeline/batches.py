"""One trace batch: receivers in, per-cell features (and per-path rows) out; saved to and read from the work folder.

The unit of resumable work: ``batch_<b>.npz`` files in a build's work folder are finished batches. Every executor
(serial in :mod:`dtradar_data.pipeline.tracing`, Ray in :mod:`dtradar_data.pipeline.executors`) traces with
:func:`trace_batch` and stores with :func:`save_batch`, so their results are the same bytes.
"""

from __future__ import annotations

import hashlib
import io
import pickle
import zipfile
import zlib
from pathlib import Path

import numpy as np

from dtradar_data.core.files import write_atomic
from dtradar_data.core.schema import tx_column
from dtradar_data.rt import features


def batch_path(work_dir: Path, b: int) -> Path:
    return work_dir / f"batch_{b:05d}.npz"


def batch_layout(n_cells: int, settings) -> int:
    """The cells per trace call for a grid of ``n_cells`` free cells.

    Sionna's own solver: ``settings.batch_size``, a part of the version (a cell's row depends on its batch).
    Batch-independent tracing: as few calls as ``batch_size`` allows, made even (Dallas Q3's 1 950 cells at 1 024:
    two calls of 975 instead of 1 024 + 926), so that Ray's workers finish together; the rows do not change."""
    if not settings.batch_independent:
        return settings.batch_size
    calls = max(1, -(-n_cells // settings.batch_size))
    return max(1, -(-n_cells // calls))


def batch_dir(work_dir: Path, settings, size: int) -> Path:
    """Where a build's batch files go: its work folder, or with batch-independent tracing (whose version leaves the
    batch size out) a folder per layout in it, so a build resumed with another ``--rt.batch-size`` never reads a
    batch file of another size as one of its own."""
    return work_dir / f"batches-of-{size}" if settings.batch_independent else work_dir


def trace_batch(
    tracer, points: np.ndarray, ix: np.ndarray, iy: np.ndarray, *, per_path: bool
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Trace ``points`` (receivers of the cells ``ix``, ``iy``) and reduce them to ``(cells, paths)`` arrays.

    With ``--rt.batch-independent``, besides the radio features, ``cells["retrace_depth"]`` (int8) says how many
    times the cell's PathSolver call was halved because its path buffer filled (0: traced with the whole batch; -1:
    the cell filled it on its own), for the dataset card: ``(retrace_depth != 0).sum()`` cells were re-traced."""
    if getattr(tracer, "num_tx", 1) > 1:
        return _trace_each(tracer, points, ix, iy, per_path=per_path)
    batch = tracer.trace(points)
    if not tracer.settings.batch_independent:  # Sionna's own solver: the rows of every stored version, unchanged
        cells = features.reduce_cells(batch)
        paths = features.path_rows(batch, ix, iy) if per_path else {}
        return cells, paths
    cells = _reduce_cells(batch)
    cells["retrace_depth"] = np.asarray(tracer.last_retrace_depth, np.int8)
    paths = features.path_rows(batch, ix, iy) if per_path else {}
    return cells, paths


def _trace_each(tracer, points, ix, iy, *, per_path: bool):
    """:func:`trace_batch` of a scene with several transmitters: one trace, transmitter ``k``'s features under
    ``tx{k}_`` keys (:func:`~dtradar_data.core.schema.tx_column`), its paths with ``tx = k``."""
    reduce = _reduce_cells if tracer.settings.batch_independent else features.reduce_cells
    cells: dict[str, np.ndarray] = {}
    paths: list[dict[str, np.ndarray]] = []
    for k, batch in enumerate(tracer.trace_each(points)):
        cells.update({tx_column(key, k): v for key, v in reduce(batch).items()})
        if per_path:
            rows = features.path_rows(batch, ix, iy)
            rows["tx"] = np.full(len(rows["ix"]), k, np.int16)
            paths.append(rows)
    if tracer.settings.batch_independent:
        cells["retrace_depth"] = np.asarray(tracer.last_retrace_depth, np.int8)
    merged = {key: np.concatenate([p[key] for p in paths]) for key in paths[0]} if paths else {}
    return cells, merged


def _reduce_cells(batch) -> dict[str, np.ndarray]:
    """:func:`features.reduce_cells`, applied to the receivers of each path count separately, each trimmed to its own
    paths: numpy's pairwise sums over a row depend on the row's padded width (the batch's most paths), which would
    change a cell's delay spread in its last bits with the batch it was traced in."""
    import dataclasses

    if batch.valid.shape[1] == 0:  # no receiver of the call has a path (argmax of an empty row would raise)
        width = np.zeros(batch.valid.shape[0], np.int64)
    else:
        width = np.where(batch.valid.any(axis=1), batch.valid.shape[1] - np.argmax(batch.valid[:, ::-1], axis=1), 0)
    out: dict[str, np.ndarray] = {}
    for w in np.unique(width):
        rows = np.flatnonzero(width == w)
        part = {}
        for f in dataclasses.fields(batch):
            x = getattr(batch, f.name)
            if isinstance(x, np.ndarray):  # receivers and paths are the last two axes ([N, P], [D, N, P], ...)
                x = np.ascontiguousarray(x[..., rows, :w])
            part[f.name] = x
        reduced = features.reduce_cells(dataclasses.replace(batch, **part))
        for k, v in reduced.items():
            if k not in out:
                out[k] = np.empty(len(width), v.dtype)
            out[k][rows] = v
    return out


#: The member of a batch file holding the sha256 of its other members' bytes (written last, checked on load).
HASH_MEMBER = "sha256.txt"


class DamagedBatchError(ValueError):
    """A batch file that cannot be trusted (damaged, cut short, unreadable): it is traced again."""


def _members_digest(zf: zipfile.ZipFile) -> str:
    """The sha256 of every array member of a batch file (name and stored ``.npy`` bytes), in name order."""
    h = hashlib.sha256()
    for name in sorted(n for n in zf.namelist() if n != HASH_MEMBER):
        h.update(name.encode() + b"\0")
        h.update(zf.read(name))
    return h.hexdigest()


def save_batch(path: Path, cells: dict[str, np.ndarray], paths: dict[str, np.ndarray]) -> None:
    """Write a finished batch through a temporary file and a rename: a batch file is whole or absent, and carries
    the sha256 of its arrays (:data:`HASH_MEMBER`), so a file damaged in place is noticed on load, not traced from."""
    buf = io.BytesIO()
    np.savez(buf, **{f"c_{k}": v for k, v in cells.items()}, **{f"p_{k}": v for k, v in paths.items()})
    with zipfile.ZipFile(buf, "a") as zf:
        zf.writestr(HASH_MEMBER, _members_digest(zf))
    write_atomic(path, buf.getvalue())


def load_batch(path: Path) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The arrays of a batch file; :class:`DamagedBatchError` naming it when its bytes differ from its sha256, or it
    cannot be read whole (a batch written before the hash was recorded is checked by the zip's CRC-32 alone)."""
    try:
        with zipfile.ZipFile(path) as zf:
            if HASH_MEMBER in zf.namelist() and zf.read(HASH_MEMBER).decode() != _members_digest(zf):
                raise DamagedBatchError(f"{path} does not match its content hash (damaged)")
        with np.load(path, allow_pickle=True) as z:
            cells = {k[2:]: z[k] for k in z.files if k.startswith("c_")}
            paths = {k[2:]: z[k] for k in z.files if k.startswith("p_")}
    except DamagedBatchError:
        raise
    except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile, zlib.error, pickle.UnpicklingError) as e:
        raise DamagedBatchError(f"{path} cannot be read whole ({type(e).__name__}: {e})") from e
    return cells, paths
