"""The local store of logged datasets: layout, atomic writes of one version, installs of a download, checked reads.

``<root>/logged/<scene>/<variant>/<behaviour>/<version>/{transitions.parquet, meta.json, README.md}`` and
``.../<behaviour>/refs.json``: a tree apart from ``<root>/datasets`` so that RT listings never see them. A version is
written into a staging folder under ``<root>/work`` and renamed into place (complete or absent), as for RT datasets
(:mod:`dtradar_data.store.writing`).
"""

from __future__ import annotations

import json
import shutil
import tempfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
from filelock import FileLock

from dtradar_data.core import layout as P
from dtradar_data.core.errors import CorruptDatasetError, DatasetNotFoundError
from dtradar_data.core.files import json_safe, sha256_file, write_atomic
from dtradar_data.core.ids import HASH_RE, LoggedId, is_tag, parse_logged_id
from dtradar_data.store.logged.card import render_logged_card
from dtradar_data.store.logged.dataset import LoggedDataset
from dtradar_data.store.logged.table import TRANSITIONS_FILE, TRANSITIONS_FORMAT, check_transitions, episode_stats
from dtradar_data.store.logged.versions import logged_version
from dtradar_data.store.versions import Refs, read_refs, resolve_revision, write_refs

__all__ = [
    "LOGGED_DIR",
    "META_KEY",
    "logged_root",
    "logged_dir",
    "refs_path",
    "local_versions",
    "write_logged",
    "check_version_dir",
    "install_logged",
    "read_meta",
    "resolve_logged",
    "read_transitions",
    "load_logged",
]

LOGGED_DIR = "logged"
META_KEY = b"dtradar.logged"


def logged_root() -> Path:
    return P.data_root() / LOGGED_DIR


def logged_dir(lid: LoggedId) -> Path:
    return logged_root() / lid.scene / lid.variant / lid.behaviour


def refs_path(lid: LoggedId) -> Path:
    return logged_dir(lid) / P.REFS_FILE


def local_versions(lid: LoggedId) -> list[str]:
    """Version folders of ``lid`` (complete ones: with meta.json), oldest tag first."""
    d = logged_dir(lid)
    if not d.is_dir():
        return []
    found = [p.name for p in d.iterdir() if p.is_dir() and HASH_RE.fullmatch(p.name) and (p / P.META_FILE).is_file()]
    order = {v: i for i, (_, v) in enumerate(read_refs(refs_path(lid)).ordered())}
    return sorted(found, key=lambda v: (order.get(v, len(order)), v))


def write_logged(
    name: str | LoggedId, inputs: dict[str, Any], table: pa.Table, meta: dict[str, Any]
) -> tuple[str, Path]:
    """Store a logged version atomically (reused when it exists) and tag it; returns ``(version, directory)``.

    ``meta`` is stored in ``meta.json`` with the name, version, inputs, table stats, file hashes and creation time
    added; the card is rendered from it."""
    lid = parse_logged_id(name).with_revision(None)
    check_transitions(table)
    version = logged_version(inputs)
    ddir = logged_dir(lid)
    ddir.mkdir(parents=True, exist_ok=True)
    with FileLock(ddir / ".lock"):
        vdir = ddir / version
        refs = read_refs(refs_path(lid))
        if not (vdir / P.META_FILE).is_file():
            if vdir.exists():
                shutil.rmtree(vdir)  # a leftover without meta.json never became a version
            P.work_root().mkdir(parents=True, exist_ok=True)
            stage = Path(tempfile.mkdtemp(prefix="logged-", dir=P.work_root()))
            try:
                full = {
                    **json_safe(meta),
                    "name": lid.name,
                    "version": version,
                    "format": TRANSITIONS_FORMAT,
                    "inputs": json_safe(inputs),
                    "parent": inputs["parent"],
                    "parent_version": inputs["parent_version"],
                    "behaviour": inputs["behaviour"],
                    "steps": inputs["steps"],
                    "seed": inputs["seed"],
                    "settings": inputs["settings"],
                    "library_versions": inputs["library_versions"],
                    "stats": {
                        **episode_stats(table, (inputs.get("settings") or {}).get("max_steps")),
                        **json_safe(meta.get("stats") or {}),
                    },
                    "created_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                }
                schema_meta = {META_KEY: json.dumps({"name": lid.name, "version": version}).encode()}
                pq.write_table(
                    table.replace_schema_metadata(schema_meta),
                    stage / TRANSITIONS_FILE,
                    compression="zstd",
                    write_page_checksum=True,
                )
                f = stage / TRANSITIONS_FILE
                full["files"] = {TRANSITIONS_FILE: {"sha256": sha256_file(f), "bytes": f.stat().st_size}}
                tag = refs.tag_of(version) or refs.next_tag()
                write_atomic(stage / P.META_FILE, json.dumps(full, indent=2, sort_keys=True) + "\n")
                write_atomic(stage / P.CARD_FILE, render_logged_card(full, tag))
                stage.rename(vdir)
            except BaseException:
                shutil.rmtree(stage, ignore_errors=True)
                raise
        if refs.tag_of(version) is None:
            refs = Refs({**refs.tags, refs.next_tag(): version}, version)
            write_refs(refs_path(lid), refs)
    return version, vdir


def check_version_dir(vdir: Path) -> tuple[str, dict[str, Any]]:
    """Verify a version folder that is not (yet) in the store, e.g. a download: its record, the file's sha256, the
    table's invariants, and that the version is the hash of the recorded logging inputs. Returns ``(version, meta)``
    or raises :class:`CorruptDatasetError` / :class:`SchemaMismatchError`."""
    meta = read_meta(vdir)
    version = meta.get("version")
    if not isinstance(meta.get("inputs"), dict) or logged_version(meta["inputs"]) != version:
        raise CorruptDatasetError(
            f"{vdir / P.META_FILE}: version {version!r} is not the hash of its logging inputs",
            hint="the record was edited or damaged; log or pull the dataset again",
        )
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file() or sha256_file(f) != rec.get("sha256"):
        raise CorruptDatasetError(
            f"{f} is missing or its sha256 differs from meta.json", hint="log or pull the dataset again"
        )
    read_transitions(f)
    return version, meta


def install_logged(name: str | LoggedId, staged: Path, *, preferred_tag: str | None = None) -> Path:
    """Move a verified version folder (:func:`check_version_dir`) into the store and tag it (``preferred_tag`` when
    it is free, e.g. the publisher's tag; else the next one). An existing version is kept; returns its folder."""
    lid = parse_logged_id(name).with_revision(None)
    version, meta = check_version_dir(staged)
    if meta.get("name") != lid.name:
        raise CorruptDatasetError(
            f"{staged} holds {meta.get('name')!r}, not {lid.name!r}", hint="pull it under its own name"
        )
    ddir = logged_dir(lid)
    ddir.mkdir(parents=True, exist_ok=True)
    with FileLock(ddir / ".lock"):
        vdir = ddir / version
        if not (vdir / P.META_FILE).is_file():
            if vdir.exists():
                shutil.rmtree(vdir)
            shutil.move(str(staged), vdir)
        refs = read_refs(refs_path(lid))
        if refs.tag_of(version) is None:
            tag = (
                preferred_tag
                if preferred_tag and is_tag(preferred_tag) and preferred_tag not in refs.tags
                else refs.next_tag()
            )
            write_refs(refs_path(lid), Refs({**refs.tags, tag: version}, version))
    return vdir


def read_meta(vdir: Path) -> dict[str, Any]:
    try:
        meta = json.loads((vdir / P.META_FILE).read_text())
        if not isinstance(meta, dict) or meta.get("format") != TRANSITIONS_FORMAT:
            raise ValueError(
                f"format {meta.get('format') if isinstance(meta, dict) else None!r}, expected {TRANSITIONS_FORMAT}"
            )
        return meta
    except (OSError, ValueError) as exc:
        raise CorruptDatasetError(
            f"{vdir / P.META_FILE} is not a logged-dataset record ({exc})",
            hint="log the dataset again (`python -m dtradar_rl log ...`)",
        ) from exc


def resolve_logged(name: str | LoggedId, revision: str | None = None) -> tuple[LoggedId, str, Path]:
    lid = parse_logged_id(name)
    revision = revision or lid.revision
    versions = local_versions(lid)
    if not versions:
        raise DatasetNotFoundError(
            f"logged dataset {lid.name} is not in {logged_root()}",
            hint=f"log it: `python -m dtradar_rl log --scene {lid.scene} --variant "
            f"{lid.variant} --behaviour {lid.behaviour}` (or `make logged`)",
        )
    version = resolve_revision(read_refs(refs_path(lid)), versions, revision, lid.name)
    return lid, version, logged_dir(lid) / version


def read_transitions(path: Path) -> pa.Table:
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise CorruptDatasetError(
            f"{path} cannot be read as Parquet ({exc})", hint="log the dataset again or re-pull it"
        ) from exc
    check_transitions(table.replace_schema_metadata(None), str(path))
    return table.replace_schema_metadata(None)


def load_logged(name: str | LoggedId, revision: str | None = None, *, verify: bool = True) -> LoggedDataset:
    """Load a logged version: the newest without ``revision`` (or ``@rev`` in ``name``), else a tag or hash.
    ``verify`` re-hashes the file against ``meta.json``; the table is always checked (:func:`check_transitions`)."""
    lid, version, vdir = resolve_logged(name, revision)
    meta = read_meta(vdir)
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file():
        raise CorruptDatasetError(f"{f} is missing", hint="log the dataset again")
    if verify and sha256_file(f) != rec.get("sha256"):
        raise CorruptDatasetError(
            f"{f}: sha256 differs from meta.json (changed or damaged)", hint=f"log it again, or remove {vdir}"
        )
    table = read_transitions(f)
    tag = read_refs(refs_path(lid)).tag_of(version)
    meta["tag"] = tag
    return LoggedDataset(lid.name, version, tag, table, meta, vdir)
