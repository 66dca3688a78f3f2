"""Where datasets live on disk. Every path the store touches is built here, so the layout has one definition.

Layout (docs: Datasets, where datasets live)::

    <root>/datasets/<scene>/<variant>/<version>/{cells.parquet, paths.parquet?, coverage.png?, meta.json, README.md}
    <root>/datasets/<scene>/<variant>/<version>/scene/{scene.xml, meshes/*.ply, base/...}   the traced scene
    <root>/datasets/<scene>/<variant>/refs.json      {"tags": {"v0": "<version>", ...}, "latest": "<version>"}
    <root>/work/                                      staging (temp dirs renamed into place), pipeline scratch

``<root>`` is ``$DTRADAR_DATA_ROOT``, default ``~/.cache/dtradar``. Staging lives under the same root so the final
``os.rename`` never crosses a filesystem boundary (a cross-device rename would not be atomic).
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

from dtradar_data.core.errors import DataRootError

ENV_DATA_ROOT = "DTRADAR_DATA_ROOT"
DEFAULT_DATA_ROOT = Path("~/.cache/dtradar")

CELLS_FILE = "cells.parquet"
PATHS_FILE = "paths.parquet"
COVERAGE_FILE = "coverage.png"
#: Pictures a card may show besides the coverage map: a city quadrant's place in its city, a moving twin's
#: animation.
CITY_FILE = "city.png"
MOVING_GIF_FILE = "moving.gif"
#: The picture of the stored table itself (cells.parquet's path gain per cell, per transmitter, on one dB scale):
#: what an agent reads, beside the radio map's estimate on a finer grid (dtradar_data.pipeline.cells_picture).
CELLS_PICTURE_FILE = "cells.png"
#: Every picture a version may hold, in the order a build names them.
PICTURE_FILES = (COVERAGE_FILE, CELLS_PICTURE_FILE, CITY_FILE, MOVING_GIF_FILE)
META_FILE = "meta.json"
#: The folder holding the Mitsuba scene a version was traced from (``scene.xml`` and the meshes it names, by relative
#: paths), so that ``sionna.rt.load_scene`` opens it without dtradar; files in it are listed in ``meta.json`` by their
#: path below the version folder (``scene/meshes/wood.ply``).
SCENE_DIR = "scene"
SCENE_XML = f"{SCENE_DIR}/scene.xml"
CARD_FILE = "README.md"
REFS_FILE = "refs.json"


def _fix() -> str:
    return f"set {ENV_DATA_ROOT} to a folder you can write to (unset, it is {DEFAULT_DATA_ROOT})"


def data_root() -> Path:
    """The data root: ``$DTRADAR_DATA_ROOT`` if set (read on every call, so tests can monkeypatch it).

    :class:`DataRootError` when it, or a folder above it, is a file: every read below it would otherwise look like
    an empty store, and every write would fail deep inside with ``NotADirectoryError``.
    """
    value = os.environ.get(ENV_DATA_ROOT, "").strip()
    root = Path(value).expanduser() if value else DEFAULT_DATA_ROOT.expanduser()
    existing = _nearest_existing(root)
    if not existing.is_dir():
        raise DataRootError(
            f"data root {root} is not a folder: {existing} is a file", hint=f"move {existing} away, or {_fix()}"
        )
    return root


def _nearest_existing(path: Path) -> Path:
    return next(p for p in (path, *path.parents) if p.exists())


def writable_data_root() -> Path:
    """The data root, checked to be writable (or creatable) before a build or a pull starts its expensive work."""
    root = data_root()
    existing = _nearest_existing(root)
    if not os.access(existing, os.W_OK | os.X_OK):
        what = f"data root {root}" + ("" if existing == root else f" cannot be created: {existing}")
        raise DataRootError(f"{what} is read-only", hint=f"make it writable, or {_fix()}")
    return root


def datasets_root() -> Path:
    return data_root() / "datasets"


def work_root() -> Path:
    """Scratch space for builds and staging; anything here may be deleted when no build is running. Only writers
    ask for it, so it is where a read-only data root is refused."""
    return writable_data_root() / "work"


def work_root_to_read() -> Path:
    """Where :func:`work_root` is, for a reader that only looks into it (for the locks live writers hold there): a
    read-only data root (a shared mirror, a container image) is no error here, and nothing is created."""
    return data_root() / "work"


def dataset_dir(scene: str, variant: str) -> Path:
    """``<root>/datasets/<scene>/<variant>``: all versions of one dataset plus its ``refs.json``."""
    return datasets_root() / scene / variant


def version_dir(scene: str, variant: str, version: str) -> Path:
    return dataset_dir(scene, variant) / version


def refs_path(scene: str, variant: str) -> Path:
    return dataset_dir(scene, variant) / REFS_FILE


def is_scene_file(name: str) -> bool:
    """Whether ``name`` (as ``meta.json`` lists a version's files) is a relative path inside the version's scene
    folder, without ``..`` or hidden parts: the one place of a version with sub-folders."""
    parts = PurePosixPath(name).parts
    return (
        len(parts) >= 2
        and parts[0] == SCENE_DIR
        and "\\" not in name
        and all(p not in ("", ".", "..") and not p.startswith(".") for p in parts)
    )
