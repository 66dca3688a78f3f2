"""Small file helpers shared by every layer: atomic text writes, file hashes, JSON-safe values."""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from dtradar_data.core.errors import MissingDependencyError


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
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
