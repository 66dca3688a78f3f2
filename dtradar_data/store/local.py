"""The local dataset store: versioned Parquet under the data root, written atomically, read with checks.

Writing (:func:`write_version`): everything goes into a staging directory under ``<root>/work/``; the Parquet files
carry the explicit :data:`~dtradar_data.core.schema.CELL_SCHEMA` / ``PATH_SCHEMA`` (zstd, page checksums) and the build
metadata as JSON under the schema-metadata key ``b"dtradar.meta"``; ``meta.json`` records the sha256 and size of every
data file. Only then is the directory renamed into ``<root>/datasets/<scene>/<variant>/<version>`` (one ``rename``:
a version is either complete or absent) and ``refs.json`` replaced atomically. A failure anywhere removes the staging
directory and leaves existing versions untouched; an existing version is never rewritten.

Reading (:func:`load`): the cells file is re-hashed against ``meta.json`` (cheap next to decoding it), its schema is
compared with the expected one column by column, and Parquet page checksums are verified while decoding. The
per-path table is read eagerly, and only when asked for (``load(name, paths=True)``): it can be many times larger
than the cell table and most consumers never need it.
"""

from __future__ import annotations

import copy
import json
import logging
import os
import shutil
import tempfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from filelock import FileLock

from dtradar_data.core import layout as P
from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    DtradarError,
    RevisionNotFoundError,
    SchemaMismatchError,
)
from dtradar_data.core.files import json_safe, sha256_file
from dtradar_data.core.ids import HASH_RE, DatasetId
from dtradar_data.core.record import RECORD_FORMAT, VersionRecord
from dtradar_data.core.schema import CELL_SCHEMA, PATH_SCHEMA, SCHEMA_VERSION
from dtradar_data.store.card import render_version_card
from dtradar_data.store.catalog import as_id
from dtradar_data.store.versions import Refs, read_refs, resolve_revision, write_refs

log = logging.getLogger(__name__)

META_KEY = b"dtradar.meta"
#: Files the store itself writes; ``extra_files`` may not shadow them.
RESERVED_FILES = frozenset({P.CELLS_FILE, P.PATHS_FILE, P.META_FILE, P.CARD_FILE})


class InvalidTableError(DtradarError, ValueError):
    """A table whose rows do not form the grid described by its metadata, or metadata that is unusable."""


# ---------------------------------------------------------------------------------------------------------- schema


def schema_diff(actual: pa.Schema, expected: pa.Schema) -> list[str]:
    """Human-readable differences (missing/extra columns, types, nullability); empty when the schemas agree."""
    have = {f.name: f for f in actual}
    want = {f.name: f for f in expected}
    out = [f"missing column {n!r} ({want[n].type})" for n in want if n not in have]
    out += [f"extra column {n!r} ({have[n].type})" for n in have if n not in want]
    for n, f in want.items():
        if n in have:
            g = have[n]
            if g.type != f.type:
                out.append(f"column {n!r} has type {g.type}, expected {f.type}")
            elif g.nullable and not f.nullable:
                out.append(f"column {n!r} is nullable, expected non-null")
    return out


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
            f"{what} does not match the schema (v{SCHEMA_VERSION}): " + "; ".join(diff),
            hint="fix the table producer, or bump SCHEMA_VERSION with a new golden file",
        )
    return pa.Table.from_arrays([table.column(f.name) for f in schema], schema=schema)


def _check_grid(cells: pa.Table, meta: dict[str, Any]) -> pa.Table:
    """Sort row-major and check that the rows are exactly the ``nx × ny`` grid of ``meta['grid']``."""
    try:
        nx, ny = int(meta["grid"]["nx"]), int(meta["grid"]["ny"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidTableError(
            "meta has no usable 'grid' (x0_m, y0_m, cell_m, nx, ny)",
            hint="pass meta['grid'] = scene_spec.grid.to_dict()",
        ) from exc
    cells = cells.sort_by([("iy", "ascending"), ("ix", "ascending")])
    ix = cells.column("ix").to_numpy()
    iy = cells.column("iy").to_numpy()
    gy, gx = np.divmod(np.arange(nx * ny), nx)
    if cells.num_rows != nx * ny or not (np.array_equal(ix, gx) and np.array_equal(iy, gy)):
        raise InvalidTableError(
            f"cells has {cells.num_rows} rows that are not the {nx}x{ny} grid (one row per (ix, iy), "
            f"0 <= ix < {nx}, 0 <= iy < {ny})",
            hint="emit one row per grid cell, blocked cells included",
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


def _locked(directory: Path) -> FileLock:
    """An exclusive lock per dataset (a ``.lock`` file in its folder), so two processes cannot hand out one tag."""
    directory.mkdir(parents=True, exist_ok=True)
    return FileLock(directory / ".lock")


# ------------------------------------------------------------------------------------------------------- writing


def version_exists(dataset_id: str | DatasetId, version: str) -> bool:
    did = as_id(dataset_id, check_known=False)
    return (P.version_dir(did.scene, did.variant, version) / P.META_FILE).is_file()


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
    ``extra_files`` maps a file name in the version directory (e.g. ``coverage.png``) to a source path.
    """
    did = as_id(dataset_id, check_known=False)
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
    final = P.version_dir(did.scene, did.variant, version)
    if version_exists(did, version):
        log.info("%s: version %s exists, reusing it", did.name, version)
        return final
    check_can_store(did, version)

    if int(meta.get("schema_version", SCHEMA_VERSION)) != SCHEMA_VERSION:
        raise SchemaMismatchError(
            f"meta says schema_version {meta['schema_version']}, this library writes v{SCHEMA_VERSION}",
            hint="rebuild the table with this library version",
        )
    cells = _check_grid(conform(cells, CELL_SCHEMA, f"cells table of {did.name}"), meta)
    if paths is not None:
        paths = conform(paths, PATH_SCHEMA, f"paths table of {did.name}").sort_by(
            [("iy", "ascending"), ("ix", "ascending"), ("path", "ascending")]
        )
    extra_files = dict(extra_files or {})
    for fname, src in extra_files.items():
        if fname in RESERVED_FILES or Path(fname).name != fname or fname.startswith("."):
            raise InvalidTableError(
                f"extra file name {fname!r} is reserved or not a plain file name",
                hint=f"use a plain name other than {sorted(RESERVED_FILES)}",
            )
        if not Path(src).is_file():
            raise InvalidTableError(f"extra file {fname!r}: {src} does not exist", hint="write it before storing")

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
    meta.setdefault("created_utc", datetime.now(timezone.utc).isoformat(timespec="seconds"))
    meta.pop("files", None)
    # The Parquet copy of the metadata is the content description only: file hashes cannot include themselves.
    meta_json = json.dumps(meta, sort_keys=True, ensure_ascii=False, allow_nan=False).encode()

    P.work_root().mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f"stage-{did.scene}-{did.variant}-{version}-", dir=P.work_root()))
    try:
        _write_parquet(cells, stage / P.CELLS_FILE, meta_json)
        if paths is not None:
            _write_parquet(paths, stage / P.PATHS_FILE, meta_json)
        for fname, src in sorted(extra_files.items()):
            shutil.copyfile(src, stage / fname)
        meta["files"] = {
            f.name: {"sha256": sha256_file(f), "bytes": f.stat().st_size}
            for f in sorted(stage.iterdir())
            if f.is_file()
        }
        return _install(did, version, stage, meta)
    finally:
        shutil.rmtree(stage, ignore_errors=True)  # after a successful install the stage is gone already


def _install(did: DatasetId, version: str, stage: Path, meta: dict[str, Any], preferred_tag: str | None = None) -> Path:
    """Under the dataset lock: tag, write meta.json and the card into ``stage``, rename it into place."""
    ddir = P.dataset_dir(did.scene, did.variant)
    final = ddir / version
    with _locked(ddir):
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


# ------------------------------------------------------------------------------------------------------- reading


def read_meta(version_dir: Path) -> dict[str, Any]:
    """The ``meta.json`` of a version as a dict, checked against :class:`VersionRecord` (and migrated to its
    current format), so damage shows here as a typed error naming the file."""
    path = version_dir / P.META_FILE
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise CorruptDatasetError(f"{path} is missing", hint="rebuild the dataset or re-pull it") from exc
    except (ValueError, UnicodeDecodeError) as exc:
        raise CorruptDatasetError(
            f"{path} is not valid JSON ({exc})", hint="rebuild the dataset or re-pull it"
        ) from exc
    return VersionRecord.from_meta(meta, where=str(path)).to_meta()


def read_table(path: Path, schema: pa.Schema) -> pa.Table:
    """Read one Parquet file, checking its schema and page checksums; typed errors name the file."""
    fix = "rebuild it (`make dataset SCENE=<scene>`) or re-pull it (`python -m dtradar_data pull NAME`)"
    try:
        pf = pq.ParquetFile(path, page_checksum_verification=True)
        actual = pf.schema_arrow
    except FileNotFoundError as exc:
        raise CorruptDatasetError(f"{path} is missing", hint=fix) from exc
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise CorruptDatasetError(f"{path} is not a readable Parquet file ({exc})", hint=fix) from exc
    diff = schema_diff(actual, schema)
    if diff:
        raise SchemaMismatchError(
            f"{path} does not match the expected schema: " + "; ".join(diff),
            hint="it was written by another schema version or edited: " + fix,
        )
    try:
        table = pf.read()
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise CorruptDatasetError(f"{path} is corrupt ({exc})", hint=fix) from exc
    return table.replace_schema_metadata(schema.metadata)


def _check_hash(version_dir: Path, fname: str, meta: dict[str, Any]) -> None:
    expected = (meta.get("files") or {}).get(fname, {}).get("sha256")
    if expected and sha256_file(version_dir / fname) != expected:
        raise CorruptDatasetError(
            f"{version_dir / fname} does not match the sha256 recorded in meta.json (changed or damaged on disk)",
            hint="rebuild the dataset or re-pull it; `python -m dtradar_data verify NAME` checks every file",
        )


def local_versions(did: DatasetId, *, damaged: bool = False) -> list[str]:
    """Version directories on disk, oldest first (tag order, then creation time for untagged ones).

    Only those with a ``meta.json``, unless ``damaged``: then also folders without one, for ``verify`` to report.
    """
    ddir = P.dataset_dir(did.scene, did.variant)
    if not ddir.is_dir():
        return []
    found = [
        p.name
        for p in ddir.iterdir()
        if HASH_RE.fullmatch(p.name) and p.is_dir() and (damaged or (p / P.META_FILE).is_file())
    ]
    refs = read_refs(ddir / P.REFS_FILE)
    order = {v: i for i, (_, v) in enumerate(refs.ordered())}

    def created(v: str) -> float:
        meta = ddir / v / P.META_FILE
        return (meta if meta.is_file() else ddir / v).stat().st_mtime

    return sorted(found, key=lambda v: (order.get(v, len(order)), created(v), v))


def damaged_versions(did: DatasetId) -> dict[str, str]:
    """``{version: problem}`` of the version folders whose ``meta.json`` is missing or unreadable: listed as
    damaged rather than hidden (a missing one) or failing every listing (an unreadable one)."""
    out = {}
    for version in local_versions(did, damaged=True):
        try:
            read_meta(P.version_dir(did.scene, did.variant, version))
        except CorruptDatasetError as exc:
            out[version] = exc.message
    return out


def check_can_store(dataset_id: str | DatasetId, version: str) -> None:
    """Refuse, before a build traces anything, what would make storing ``version`` fail at the end: a leftover
    folder of that version without ``meta.json``, or a stored version whose ``meta.json`` the card history cannot
    read."""
    did = as_id(dataset_id, check_known=False)
    folder = P.version_dir(did.scene, did.variant, version)
    damaged = damaged_versions(did)
    if version in damaged:
        raise CorruptDatasetError(
            f"{folder} exists but is damaged ({damaged[version]})",
            hint=f"remove that folder (`rm -r {folder}`) and build again",
        )
    unreadable = [v for v in damaged if (P.version_dir(did.scene, did.variant, v) / P.META_FILE).is_file()]
    if unreadable:
        paths = ", ".join(str(P.version_dir(did.scene, did.variant, v) / P.META_FILE) for v in unreadable)
        raise CorruptDatasetError(
            f"{did.name} has stored versions with an unreadable {P.META_FILE}: {paths}",
            hint=f"re-pull or remove those versions; `python -m dtradar_data verify {did.name}` lists every problem",
        )


def resolve(
    name: str | DatasetId, revision: str | None = None, *, damaged: bool = False
) -> tuple[DatasetId, str, Path]:
    """``(id, version, directory)`` of a stored version; typed errors say how to get a missing one. ``damaged``:
    also versions without ``meta.json`` (see :func:`local_versions`)."""
    did = as_id(name)
    if revision and did.revision and revision != did.revision:
        raise RevisionNotFoundError(
            f"two revisions given: {did.revision!r} in the name and {revision!r}", hint="give the revision once"
        )
    revision = revision or did.revision
    versions = local_versions(did, damaged=damaged)
    if not versions:
        raise DatasetNotFoundError(
            f"{did.name} has not been built or pulled into {P.data_root()}",
            hint=f"build it with `make dataset SCENE={did.scene}` (or `python -m dtradar_data build --scene "
            f"{did.scene} --variant {did.variant}`), or pull a published one with "
            f"`python -m dtradar_data pull {did.name}`",
        )
    refs = read_refs(P.refs_path(did.scene, did.variant))
    version = resolve_revision(refs, versions, revision, did.name)
    return did.with_revision(revision), version, P.version_dir(did.scene, did.variant, version)


def load(name: str | DatasetId, revision: str | None = None, *, paths: bool = False, verify: bool = True) -> Dataset:
    """Load a stored dataset version: the newest without ``revision`` (or ``@rev`` in ``name``), else a tag or hash.

    ``paths=True`` also reads the per-path table into ``Dataset.paths_table`` (eagerly). ``verify`` re-hashes the
    files read against ``meta.json``. (``dtradar_data.load`` adds the Hub fallback on top of this.)
    """
    did, version, vdir = resolve(name, revision)
    meta = read_meta(vdir)
    if verify:
        _check_hash(vdir, P.CELLS_FILE, meta)
    table = read_table(vdir / P.CELLS_FILE, CELL_SCHEMA)
    paths_table = None
    if paths:
        if not (vdir / P.PATHS_FILE).is_file():
            raise DatasetNotFoundError(
                f"{did.name}@{version} was built without the per-path table",
                hint="rebuild with per-path output enabled, or load without paths=True",
            )
        if verify:
            _check_hash(vdir, P.PATHS_FILE, meta)
        paths_table = read_table(vdir / P.PATHS_FILE, PATH_SCHEMA)
    refs = read_refs(P.refs_path(did.scene, did.variant))
    meta["tag"] = refs.tag_of(version)  # tags live in refs.json; handed to consumers for logging
    grid = meta.get("grid", {})
    if table.num_rows != int(grid.get("nx", -1)) * int(grid.get("ny", -1)):
        raise CorruptDatasetError(
            f"{vdir / P.CELLS_FILE} has {table.num_rows} rows, meta.json grid is {grid.get('nx')}x{grid.get('ny')}",
            hint="rebuild the dataset or re-pull it",
        )
    return Dataset(name=did.name, table=table, meta=meta, version=version, path=vdir, paths_table=paths_table)


def verify_dir(vdir: Path) -> list[str]:
    """Problems found in one version directory (empty = fine): hashes, sizes, schemas, full decode."""
    try:
        meta = read_meta(vdir)
    except CorruptDatasetError as exc:
        return [str(exc.message)]
    problems = []
    files = meta.get("files") or {}
    if P.CELLS_FILE not in files:
        problems.append(f"meta.json lists no {P.CELLS_FILE}")
    for fname, rec in sorted(files.items()):
        f = vdir / fname
        if not f.is_file():
            problems.append(f"{fname}: missing")
        elif f.stat().st_size != int(rec.get("bytes", -1)) or sha256_file(f) != rec.get("sha256"):
            problems.append(f"{fname}: sha256 differs from meta.json (changed or damaged)")
    for fname, schema in ((P.CELLS_FILE, CELL_SCHEMA), (P.PATHS_FILE, PATH_SCHEMA)):
        if (vdir / fname).is_file():
            try:
                read_table(vdir / fname, schema)
            except (CorruptDatasetError, SchemaMismatchError) as exc:
                problems.append(f"{fname}: {exc.message}")
    return problems


def history_metas(did: DatasetId, refs: Refs) -> list[tuple[str, dict[str, Any]]]:
    """``(tag, meta)`` of the stored versions, oldest first (for the card's version history)."""
    out = []
    for tag, version in refs.ordered():
        vdir = P.version_dir(did.scene, did.variant, version)
        if (vdir / P.META_FILE).is_file():
            out.append((tag, read_meta(vdir)))
    return out
