"""Reading the local dataset store: stored versions found, resolved, loaded and verified.

Every consumer of a dataset (training, the CLI, publishing, the next build's parent) reads through here, and none may
be handed a table other than the one stored, so damage has to surface at read time, as a typed error that names the
file and says how to fix it, rather than as wrong numbers later: :func:`load` re-hashes the cells file against
``meta.json`` (cheap next to decoding it), compares its schema column by column and verifies Parquet page checksums
while decoding. The per-path table is read only when asked for (``load(name, paths=True)``): it can be many times
larger than the cell table and most consumers never need it. Writing is :mod:`dtradar_data.store.writing`'s job.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dtradar_data.core import layout as P
from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    SchemaMismatchError,
)
from dtradar_data.core.files import sha256_file
from dtradar_data.core.ids import HASH_RE, DatasetId
from dtradar_data.core.record import VersionRecord
from dtradar_data.core.schema import cell_schema, meta_path_channels, meta_transmitters, path_schema
from dtradar_data.store.catalog import as_id, build_command, missing_twin
from dtradar_data.store.versions import Refs, one_revision, read_refs, resolve_revision

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


# ------------------------------------------------------------------------------------------------------- reading


def version_exists(dataset_id: str | DatasetId, version: str) -> bool:
    did = as_id(dataset_id, check_known=False)
    return (P.version_dir(did.scene, did.variant, version) / P.META_FILE).is_file()


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


def read_table(path: Path, schema: pa.Schema, *, fix: str | None = None) -> pa.Table:
    """Read one Parquet file, checking its schema and page checksums; typed errors name the file (``fix``: their
    hint, by default a generic rebuild or re-pull)."""
    fix = fix or "rebuild it (`make dataset SCENE=<scene>`) or re-pull it (`python -m dtradar_data pull NAME`)"
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


def _check_hash(version_dir: Path, fname: str, meta: dict[str, Any], fix: str) -> None:
    expected = (meta.get("files") or {}).get(fname, {}).get("sha256")
    if expected and sha256_file(version_dir / fname) != expected:
        raise CorruptDatasetError(
            f"{version_dir / fname} does not match the sha256 recorded in meta.json (changed or damaged on disk)",
            hint=fix,
        )


def damaged_hint(did: DatasetId, version: str, vdir: Path) -> str:
    """How to get a damaged stored version back: see every problem, then remove it and rebuild it or re-pull its own
    tag (both reuse a version folder that is there, damaged or not, so it has to go first)."""
    tag = read_refs(P.refs_path(did.scene, did.variant)).tag_of(version) or version
    return (
        f"`python -m dtradar_data verify {did.name}` lists every problem; remove the damaged version "
        f"(`rm -r {vdir}`), then rebuild it with {build_command(did)} or re-pull it "
        f"(`python -m dtradar_data pull {did.name}@{tag}`)"
    )


def _stored_file(vdir: Path, fname: str, what: str, fix: str) -> Path:
    """``vdir / fname``, a file the version stores, or :class:`CorruptDatasetError` naming it when it is missing."""
    path = vdir / fname
    if not path.is_file():
        raise CorruptDatasetError(f"{path} is missing: {what} is damaged", hint=fix)
    return path


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
    revision = one_revision(did.revision, revision)
    versions = local_versions(did, damaged=damaged)
    if not versions:
        raise missing_twin(did) or DatasetNotFoundError(
            f"{did.name} has not been built or pulled into {P.data_root()}",
            hint=f"build it with {build_command(did)}, or pull a published one with "
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
    did, version, vdir = resolve(name, revision, damaged=True)  # a damaged version says so, never falls back
    fix, what = damaged_hint(did, version, vdir), f"{did.name}@{version}"
    _stored_file(vdir, P.META_FILE, what, fix)
    try:
        meta = read_meta(vdir)
    except CorruptDatasetError as exc:
        raise CorruptDatasetError(exc.message, hint=fix) from exc
    moving = _is_moving(meta)
    cells = _stored_file(vdir, P.CELLS_FILE, what, fix)
    if verify:
        _check_hash(vdir, P.CELLS_FILE, meta, fix)
    table = read_table(cells, cell_schema(moving, meta_transmitters(meta)), fix=fix)
    paths_table = None
    if paths:
        if P.PATHS_FILE not in (meta.get("files") or {}) and not (vdir / P.PATHS_FILE).is_file():
            raise DatasetNotFoundError(
                f"{did.name}@{version} was built without the per-path table",
                hint="rebuild with per-path output enabled, or load without paths=True",
            )
        path_file = _stored_file(vdir, P.PATHS_FILE, what, fix)  # listed in meta.json, so stored: missing is damage
        if verify:
            _check_hash(vdir, P.PATHS_FILE, meta, fix)
        schema = path_schema(moving, meta_transmitters(meta), meta_path_channels(meta))
        paths_table = read_table(path_file, schema, fix=fix)
    refs = read_refs(P.refs_path(did.scene, did.variant))
    meta["tag"] = refs.tag_of(version)  # tags live in refs.json; handed to consumers for logging
    grid = meta.get("grid", {})
    snapshots = int((meta.get("moving") or {}).get("snapshots", 1)) if moving else 1
    if table.num_rows != int(grid.get("nx", -1)) * int(grid.get("ny", -1)) * snapshots:
        what = f" in each of {snapshots} snapshots" if moving else ""
        raise CorruptDatasetError(
            f"{vdir / P.CELLS_FILE} has {table.num_rows} rows, meta.json grid is {grid.get('nx')}x{grid.get('ny')}"
            + what,
            hint=fix,
        )
    return Dataset(name=did.name, table=table, meta=meta, version=version, path=vdir, paths_table=paths_table)


def _is_moving(meta: dict[str, Any]) -> bool:
    """Whether a version is a moving twin (``meta["moving"]``): its tables have the moving schemas."""
    return isinstance(meta.get("moving"), dict)


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
    moving = _is_moving(meta)
    k = meta_transmitters(meta)
    for fname, schema in (
        (P.CELLS_FILE, cell_schema(moving, k)),
        (P.PATHS_FILE, path_schema(moving, k, meta_path_channels(meta))),
    ):
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
