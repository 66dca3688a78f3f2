"""Storing one dataset version: checked, staged and installed atomically under the dataset's lock.

A build runs for minutes to hours while other processes may read, list or pull the same dataset, so a version must
appear complete or not at all, and a failed or concurrent store must never damage what is already there; keeping every
write here, apart from the reads of :mod:`dtradar_data.store.local`, leaves one module that creates version
directories or changes ``refs.json``. Files are written into a staging directory under ``<root>/work/`` (Parquet with
zstd, page checksums and the build metadata as JSON under the schema-metadata key ``b"dtradar.meta"``; ``meta.json``
with every data file's sha256 and size), renamed into ``<root>/datasets/<scene>/<variant>/<version>`` in one
``rename`` and tagged by replacing ``refs.json`` atomically; an existing version is never rewritten. The staging
directory is held by its process (:mod:`dtradar_data.store.staging`), as a pull's is (:mod:`dtradar_data.publish.hub`):
the next build, write or pull removes those a killed one left (:func:`clean_stages`), never one a live process holds.

A moving twin (``meta["moving"]``: :mod:`dtradar_data.core.dataset`) is stored the same way with its own schemas
(:data:`~dtradar_data.core.schema.MOVING_CELL_SCHEMA`, ``MOVING_PATH_SCHEMA``), rows sorted by ``(t, iy, ix)`` and
every snapshot checked to be the whole grid.
"""

from __future__ import annotations

import copy
import json
import logging
import os
import shutil
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dtradar_data.core import layout as P
from dtradar_data.core.errors import CorruptDatasetError, DtradarError, SchemaMismatchError
from dtradar_data.core.files import json_safe, sha256_file, waiting_lock
from dtradar_data.core.ids import DATASET_VARIANTS, HASH_RE, SCENE_RE, DatasetId
from dtradar_data.core.record import RECORD_FORMAT
from dtradar_data.core.schema import (
    MOVING_SCHEMA_VERSION,
    SCHEMA_VERSION,
    cell_schema,
    meta_path_channels,
    meta_transmitters,
    path_schema,
)
from dtradar_data.store.card import render_version_card
from dtradar_data.store.catalog import as_id
from dtradar_data.store.local import (
    check_can_store,
    history_metas,
    read_meta,
    schema_diff,
    verify_dir,
    version_exists,
)
from dtradar_data.store.staging import clean_stale_stages, held_stage
from dtradar_data.store.versions import Refs, read_refs, write_refs

log = logging.getLogger(__name__)

META_KEY = b"dtradar.meta"
#: Files the store itself writes; ``extra_files`` may not shadow them.
RESERVED_FILES = frozenset({P.CELLS_FILE, P.PATHS_FILE, P.META_FILE, P.CARD_FILE})


class InvalidTableError(DtradarError, ValueError):
    """A table whose rows do not form the grid described by its metadata, or metadata that is unusable."""


# -------------------------------------------------------------------------------------------------------- staging

_NAMED = rf"{SCENE_RE.pattern}-(?:{'|'.join(DATASET_VARIANTS)})-"
#: The staging folders under ``<root>/work`` of a version written here (``stage-<scene>-<variant>-<version>-``) and
#: of a pull (``pull-<scene>-<variant>-``): prefix -> what comes between it and ``tempfile``'s 8 characters. Neither
#: matches the logged store's ``pull-logged-<8>`` or a build's ``work/<scene>`` folders.
STAGES = {"stage-": _NAMED + r"[0-9a-f]{7,64}-", "pull-": _NAMED}
#: A stage without a lock file (an older dtradar's) is removed once nothing in it changed for this long: that
#: dtradar held it for the seconds of a write, or the minutes of a download, and it has no lock to ask.
LOCKLESS_STAGE_AGE_S = 3600.0


def stage_prefix(did: DatasetId, version: str | None = None) -> str:
    """The prefix of a stage holding ``version`` of ``did`` (None: a pull's, whose version is known once downloaded)."""
    return f"stage-{did.scene}-{did.variant}-{version}-" if version else f"pull-{did.scene}-{did.variant}-"


def _lockless_stage(stage: Path) -> bool:
    """Whether a lockless ``stage-`` / ``pull-`` folder is a stage an older dtradar left: a version's files only (a
    pull: its download folders only), none changed for :data:`LOCKLESS_STAGE_AGE_S`."""
    try:
        entries = list(stage.iterdir())
        if stage.name.startswith("pull-"):
            ok = all(p.name in ("download", "cache", "version") for p in entries)
        else:
            ok = all(p.is_file() for p in entries)
        newest = max((p.stat().st_mtime for p in [stage, *stage.rglob("*")]), default=0.0)
    except OSError:
        return False
    return ok and time.time() - newest > LOCKLESS_STAGE_AGE_S


def clean_stages() -> list[Path]:
    """Remove the staging folders under ``<root>/work`` that a killed build, write or pull left (none a live process
    holds); returns them. A build does it first (its disk check then counts what they held), every write and pull
    too."""
    work = P.data_root() / "work"
    return [
        p
        for prefix, infix in STAGES.items()
        for p in clean_stale_stages(work, prefix, infix=infix, lockless=_lockless_stage)
    ]


# ---------------------------------------------------------------------------------------------------------- schema


def conform(table: pa.Table, schema: pa.Schema, what: str) -> pa.Table:
    """``table`` with exactly ``schema`` (column order, field descriptions), or :class:`SchemaMismatchError`.

    Types must already match: silently casting e.g. float64 angles to float32 would hide a pipeline bug.
    """
    diff = [d for d in schema_diff(table.schema, schema) if "is nullable" not in d]
    for f in schema:  # a nullable Arrow field is fine if it holds no nulls where the contract forbids them
        if not f.nullable and f.name in table.column_names and table.column(f.name).null_count:
            diff.append(f"column {f.name!r} has {table.column(f.name).null_count} nulls, expected none")
    if diff:
        raise SchemaMismatchError(
            f"{what} does not match the schema ({_schema_name(schema)}): " + "; ".join(diff),
            hint="fix the table producer, or bump SCHEMA_VERSION with a new golden file",
        )
    return pa.Table.from_arrays([table.column(f.name) for f in schema], schema=schema)


def _schema_name(schema: pa.Schema) -> str:
    """``v1``, or ``moving-cells v1`` for a moving twin's schema (they are versioned on their own)."""
    meta = schema.metadata or {}
    version = meta.get(b"dtradar.schema_version", str(SCHEMA_VERSION).encode()).decode()
    kind = meta.get(b"dtradar.table", b"").decode()
    return f"{kind} v{version}" if kind.startswith("moving") else f"v{version}"


def moving_snapshots(meta: dict[str, Any]) -> int | None:
    """``T`` of a moving twin's metadata (``meta["moving"]["snapshots"]``), None for a static twin."""
    moving = meta.get("moving")
    if moving is None:
        return None
    try:
        t = int(moving["snapshots"])
        if t < 1 or isinstance(moving["snapshots"], bool):
            raise ValueError(t)
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidTableError(
            f"meta['moving'] = {moving!r} has no usable 'snapshots' (a positive int)",
            hint="pass meta['moving'] = {'snapshots': T, 'dt_s': ..., 'movers': [...]}",
        ) from exc
    return t


def _check_grid(cells: pa.Table, meta: dict[str, Any]) -> pa.Table:
    """Sort row-major (a moving twin: by ``(t, iy, ix)``) and check that the rows are exactly the ``nx × ny`` grid
    of ``meta['grid']`` (a moving twin: that grid once per snapshot ``t = 0 .. T-1``)."""
    try:
        nx, ny = int(meta["grid"]["nx"]), int(meta["grid"]["ny"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidTableError(
            "meta has no usable 'grid' (x0_m, y0_m, cell_m, nx, ny)",
            hint="pass meta['grid'] = scene_spec.grid.to_dict()",
        ) from exc
    snapshots = moving_snapshots(meta)
    keys = [("iy", "ascending"), ("ix", "ascending")]
    if snapshots is not None:
        keys.insert(0, ("t", "ascending"))
    cells = cells.sort_by(keys)
    ix = cells.column("ix").to_numpy()
    iy = cells.column("iy").to_numpy()
    gy, gx = np.divmod(np.arange(nx * ny), nx)
    t_count = snapshots or 1
    gx, gy = np.tile(gx, t_count), np.tile(gy, t_count)
    ok = cells.num_rows == nx * ny * t_count and np.array_equal(ix, gx) and np.array_equal(iy, gy)
    if ok and snapshots is not None:
        t = cells.column("t").to_numpy()
        ok = np.array_equal(t, np.repeat(np.arange(snapshots, dtype=t.dtype), nx * ny))
    if not ok:
        what = f"the {nx}x{ny} grid"
        if snapshots is not None:
            what += f" in each of {snapshots} snapshots t = 0 .. {snapshots - 1}"
        raise InvalidTableError(
            f"cells has {cells.num_rows} rows that are not {what} (one row per (ix, iy)"
            + (", t" if snapshots else "")
            + f", 0 <= ix < {nx}, 0 <= iy < {ny})",
            hint="emit one row per grid cell, blocked cells included" + (", in every snapshot" if snapshots else ""),
        )
    if snapshots is not None:
        mover = cells.column("mover").to_numpy(zero_copy_only=False)
        blocked = cells.column("blocked").to_numpy(zero_copy_only=False)
        if (mover & ~blocked).any():
            raise InvalidTableError(
                f"{int((mover & ~blocked).sum())} cells have mover true and blocked false",
                hint="a cell a mover covers is blocked at that snapshot (blocked = obstacle or mover)",
            )
    return cells


def table_stats(cells: pa.Table) -> dict[str, Any]:
    """Counts and per-column ``{min, max, nulls}`` for the card (the pipeline's ``meta['stats']`` keys win)."""
    import pyarrow.compute as pc

    ranges = {}
    for f in cells.schema:
        if pa.types.is_floating(f.type) or pa.types.is_integer(f.type):
            mm = pc.min_max(cells.column(f.name)).as_py()
            ranges[f.name] = {"min": mm["min"], "max": mm["max"], "nulls": cells.column(f.name).null_count}
    blocked = cells.column("blocked")
    return {
        "num_cells": cells.num_rows,
        "num_free": cells.num_rows - int(pc.sum(blocked).as_py() or 0),
        "num_with_paths": int(pc.sum(pc.greater(cells.column("num_paths"), 0)).as_py() or 0),
        "num_los": int(pc.sum(cells.column("los")).as_py() or 0),
        "columns": json_safe(ranges),
    }


# ------------------------------------------------------------------------------------------------------ file utils


def _write_parquet(table: pa.Table, path: Path, meta_json: bytes) -> None:
    schema_meta = dict(table.schema.metadata or {})
    schema_meta[META_KEY] = meta_json
    pq.write_table(
        table.replace_schema_metadata(schema_meta),
        path,
        compression="zstd",
        write_page_checksum=True,
        write_statistics=True,
    )


def _locked(directory: Path, name: str):
    """An exclusive lock per dataset (a ``.lock`` file in its folder), so two processes cannot hand out one tag. It
    is held for the moment of an install only; a wait longer than a couple of seconds says whom it waits for."""
    directory.mkdir(parents=True, exist_ok=True)
    return waiting_lock(directory / ".lock", f"storing a version of {name}", notice_after_s=2.0)


# ------------------------------------------------------------------------------------------------------- writing


def write_version(
    dataset_id: str | DatasetId,
    version: str,
    cells: pa.Table,
    meta: dict[str, Any],
    *,
    paths: pa.Table | None = None,
    extra_files: dict[str, Path] | None = None,
) -> Path:
    """Store one dataset version atomically and tag it; returns its directory.

    An existing ``version`` is reused as is (same inputs, same content). ``meta`` is stored verbatim plus
    ``name``, ``scene``, ``variant``, ``version``, ``schema_version`` and ``files`` (sha256 + bytes per file).
    ``extra_files`` maps a file name in the version directory (e.g. ``coverage.png``, or a path in its scene folder,
    ``scene/scene.xml``) to a source path.
    """
    did = as_id(dataset_id, check_known=False)
    _check_name_and_version(did, version)
    final = P.version_dir(did.scene, did.variant, version)
    if version_exists(did, version):
        log.info("%s: version %s exists, reusing it", did.name, version)
        return final
    check_can_store(did, version)

    is_moving = _check_schema_versions(meta)
    cells, paths = _conformed_tables(did, cells, paths, meta, is_moving)
    extra_files = _checked_extra_files(extra_files)
    meta = _stored_meta(did, version, cells, meta, is_moving)
    # The Parquet copy of the metadata is the content description only: file hashes cannot include themselves.
    meta_json = json.dumps(meta, sort_keys=True, ensure_ascii=False, allow_nan=False).encode()

    clean_stages()
    # held: a kill leaves the stage to the next write; whatever is left of it on the way out is removed
    with held_stage(P.work_root(), stage_prefix(did, version)) as stage:
        _write_stage(stage, cells, paths, extra_files, meta_json)
        meta["files"] = _file_sums(stage)
        return _install(did, version, stage, meta)


def _check_name_and_version(did: DatasetId, version: str) -> None:
    """Refuse a dataset name with a revision, or a version that is not a lowercase hex content hash."""
    if did.revision:
        raise InvalidTableError(
            f"write_version takes a dataset name without a revision, got {did}",
            hint=f"pass {did.name!r} and the version separately",
        )
    if not isinstance(version, str) or not HASH_RE.fullmatch(version):
        raise InvalidTableError(
            f"version {version!r} is not a lowercase hex content hash",
            hint="compute it with dtradar_data.store.versions.version_id(inputs)",
        )


def _check_schema_versions(meta: dict[str, Any]) -> bool:
    """Refuse metadata of another schema version (static, or moving for a moving twin); returns whether it is moving."""
    if int(meta.get("schema_version", SCHEMA_VERSION)) != SCHEMA_VERSION:
        raise SchemaMismatchError(
            f"meta says schema_version {meta['schema_version']}, this library writes v{SCHEMA_VERSION}",
            hint="rebuild the table with this library version",
        )
    is_moving = moving_snapshots(meta) is not None
    if is_moving and int(meta.get("moving_schema_version", MOVING_SCHEMA_VERSION)) != MOVING_SCHEMA_VERSION:
        raise SchemaMismatchError(
            f"meta says moving_schema_version {meta['moving_schema_version']}, this library writes "
            f"v{MOVING_SCHEMA_VERSION}",
            hint="rebuild the moving twin with this library version",
        )
    return is_moving


def _conformed_tables(
    did: DatasetId, cells: pa.Table, paths: pa.Table | None, meta: dict[str, Any], is_moving: bool
) -> tuple[pa.Table, pa.Table | None]:
    """The cells checked to be the grid and the paths (if any), both in their schema and sorted as stored."""
    k = meta_transmitters(meta)
    cells = _check_grid(conform(cells, cell_schema(is_moving, k), f"cells table of {did.name}"), meta)
    if paths is not None:
        keys = [
            ("iy", "ascending"),
            ("ix", "ascending"),
            *([("tx", "ascending")] if k > 1 else []),
            ("path", "ascending"),
        ]
        schema = path_schema(is_moving, k, meta_path_channels(meta))
        paths = conform(paths, schema, f"paths table of {did.name}").sort_by(
            [("t", "ascending"), *keys] if is_moving else keys
        )
    return cells, paths


def _checked_extra_files(extra_files: dict[str, Path] | None) -> dict[str, Path]:
    """A copy of ``extra_files``, each a plain, unreserved name whose source file exists."""
    extra_files = dict(extra_files or {})
    for fname, src in extra_files.items():
        if (
            fname in RESERVED_FILES
            or not (Path(fname).name == fname or P.is_scene_file(fname))
            or fname.startswith(".")
        ):
            raise InvalidTableError(
                f"extra file name {fname!r} is reserved or not a plain file name",
                hint=f"use a plain name other than {sorted(RESERVED_FILES)}, or a path under {P.SCENE_DIR}/",
            )
        if not Path(src).is_file():
            raise InvalidTableError(f"extra file {fname!r}: {src} does not exist", hint="write it before storing")
    return extra_files


def _stored_meta(
    did: DatasetId, version: str, cells: pa.Table, meta: dict[str, Any], is_moving: bool
) -> dict[str, Any]:
    """A JSON-safe copy of ``meta`` with the stats, the version's names and schema versions, and no ``files``."""
    meta = json_safe(copy.deepcopy(meta))
    meta["stats"] = {**table_stats(cells), **(meta.get("stats") or {})}
    meta.update(
        name=did.name,
        scene=did.scene,
        variant=did.variant,
        version=version,
        schema_version=SCHEMA_VERSION,
        record_format=RECORD_FORMAT,
    )
    if is_moving:
        meta["moving_schema_version"] = MOVING_SCHEMA_VERSION
    meta.setdefault("created_utc", datetime.now(timezone.utc).isoformat(timespec="seconds"))
    meta.pop("files", None)
    return meta


def _write_stage(
    stage: Path, cells: pa.Table, paths: pa.Table | None, extra_files: dict[str, Path], meta_json: bytes
) -> None:
    """Write the Parquet tables and copy the extra files into ``stage``."""
    _write_parquet(cells, stage / P.CELLS_FILE, meta_json)
    if paths is not None:
        _write_parquet(paths, stage / P.PATHS_FILE, meta_json)
    for fname, src in sorted(extra_files.items()):
        (stage / fname).parent.mkdir(parents=True, exist_ok=True)  # the scene's files sit in sub-folders
        shutil.copyfile(src, stage / fname)


def _file_sums(stage: Path) -> dict[str, dict[str, Any]]:
    """``{name: {sha256, bytes}}`` of every file in ``stage``, by its path below it (meta.json's ``files``; only the
    scene's files have a folder in it: ``scene/meshes/wood.ply``)."""
    files = sorted(f for f in stage.rglob("*") if f.is_file())
    return {f.relative_to(stage).as_posix(): {"sha256": sha256_file(f), "bytes": f.stat().st_size} for f in files}


def _install(did: DatasetId, version: str, stage: Path, meta: dict[str, Any], preferred_tag: str | None = None) -> Path:
    """Under the dataset lock: tag, write meta.json and the card into ``stage``, rename it into place."""
    ddir = P.dataset_dir(did.scene, did.variant)
    final = ddir / version
    with _locked(ddir, did.name):
        if (final / P.META_FILE).is_file():  # another process finished the same version meanwhile
            return final
        refs = read_refs(ddir / P.REFS_FILE)
        tag = refs.tag_of(version)
        if tag is None:
            tag = preferred_tag if preferred_tag and preferred_tag not in refs.tags else refs.next_tag()
        (stage / P.META_FILE).write_text(json.dumps(meta, indent=2, sort_keys=True, ensure_ascii=False) + "\n")
        history = history_metas(did, refs) + [(tag, meta)]
        (stage / P.CARD_FILE).write_text(render_version_card(meta, tag=tag, history=history))
        if final.exists():  # a leftover without meta.json (e.g. copied by hand): never merge into it
            raise CorruptDatasetError(
                f"{final} exists but has no {P.META_FILE}", hint="remove that directory and build again"
            )
        os.rename(stage, final)
        refs.tags[tag] = version
        refs.latest = version if _is_newer(tag, refs) else refs.latest
        write_refs(ddir / P.REFS_FILE, refs)
    log.info("%s: stored version %s as %s in %s", did.name, version, tag, final)
    return final


def _is_newer(tag: str, refs: Refs) -> bool:
    ordered = refs.ordered()
    return not ordered or ordered[-1][0] == tag


def install_staged(dataset_id: str | DatasetId, stage: Path, *, preferred_tag: str | None = None) -> Path:
    """Install an already complete version directory (e.g. downloaded from the Hub) after verifying it fully.

    Used by :mod:`dtradar_data.publish.hub`; ``stage`` must be under the data root's work dir and is consumed.
    """
    did = as_id(dataset_id, check_known=False)
    meta = read_meta(stage)
    version = meta.get("version", "")
    if meta.get("name") != did.name or not HASH_RE.fullmatch(str(version)):
        raise CorruptDatasetError(
            f"{stage / P.META_FILE} describes {meta.get('name')!r}@{version!r}, not a version of {did.name}",
            hint="check the repository you pulled from",
        )
    problems = verify_dir(stage)
    if problems:
        raise CorruptDatasetError(
            f"downloaded {did.name}@{version} failed verification: " + "; ".join(problems),
            hint="pull again; if it persists the published files are damaged: re-publish",
        )
    if version_exists(did, version):
        return P.version_dir(did.scene, did.variant, version)
    return _install(did, version, stage, meta, preferred_tag=preferred_tag)
