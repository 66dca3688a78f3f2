"""The local store of logged datasets: layout, atomic writes of one version, installs of a download, checked reads.

``<root>/logged/<scene>/<variant>/<behaviour>/<version>/{transitions.parquet, meta.json, README.md}`` and
``.../<behaviour>/refs.json``: a tree apart from ``<root>/datasets`` so that RT listings never see them. A version is
written into a staging folder under ``<root>/work`` and renamed into place (complete or absent), as for RT datasets
(:mod:`dtradar_data.store.writing`); the staging folder is held by its process, so the next write removes those a
killed one left (:mod:`.staging`). A version folder without a readable ``meta.json`` is *damaged*, not absent:
``local_versions(lid, damaged=True)`` lists it for ``list`` and ``verify``, and logging the same settings again
replaces it (as it replaces a version whose file no longer matches its record).
"""

from __future__ import annotations

import json
import os
import shutil
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from dtradar_data.core import layout as P
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    RevisionNotFoundError,
    SchemaMismatchError,
    UnknownNameError,
    did_you_mean,
)
from dtradar_data.core.files import json_safe, sha256_file, waiting_lock, write_atomic
from dtradar_data.core.ids import HASH_RE, SCENE_RE, LoggedId, is_tag, parse_logged_id
from dtradar_data.store.logged.card import render_logged_card
from dtradar_data.store.logged.dataset import LoggedDataset
from dtradar_data.store.logged.hints import relog_hint
from dtradar_data.store.logged.staging import clean_stale_stages, held_stage
from dtradar_data.store.logged.table import TRANSITIONS_FILE, TRANSITIONS_FORMAT, check_transitions, episode_stats
from dtradar_data.store.logged.versions import logged_version
from dtradar_data.store.versions import Refs, one_revision, read_refs, resolve_revision, write_refs

__all__ = [
    "LOGGED_DIR",
    "META_KEY",
    "logged_root",
    "logged_dir",
    "refs_path",
    "local_versions",
    "logged_names",
    "id_of_dir",
    "clean_logged_stages",
    "logging_lock",
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
#: Prefixes of the staging folders under ``<root>/work`` that this package writes (a version, a pull).
STAGE_PREFIXES = ("logged-", "pull-logged-")


def looks_like_stage(stage: Path) -> bool:
    """Whether a lockless ``<root>/work`` folder of one of :data:`STAGE_PREFIXES` is a stage an older dtradar left
    (a version: files only; a pull: its download folders), not another writer's folder that shares the prefix."""
    try:
        entries = list(stage.iterdir())
    except OSError:
        return False
    if stage.name.startswith(STAGE_PREFIXES[1]):
        return all(p.name in ("download", "cache", "version") for p in entries)
    return all(p.is_file() for p in entries)


def logged_root() -> Path:
    return P.data_root() / LOGGED_DIR


def logged_dir(lid: LoggedId) -> Path:
    return logged_root() / lid.scene / lid.variant / lid.behaviour


def refs_path(lid: LoggedId) -> Path:
    return logged_dir(lid) / P.REFS_FILE


def local_versions(lid: LoggedId, *, damaged: bool = False) -> list[str]:
    """Version folders of ``lid``, oldest tag first: those with a ``meta.json``, or with ``damaged`` every one (a
    folder without it is a damaged version for ``list`` and ``verify`` to report, as for RT datasets)."""
    d = logged_dir(lid)
    if not d.is_dir():
        return []
    found = [
        p.name
        for p in d.iterdir()
        if p.is_dir() and HASH_RE.fullmatch(p.name) and (damaged or (p / P.META_FILE).is_file())
    ]
    order = {v: i for i, (_, v) in enumerate(read_refs(refs_path(lid)).ordered())}
    return sorted(found, key=lambda v: (order.get(v, len(order)), v))


def logged_names() -> list[str]:
    """Every ``scene/variant/behaviour`` with a version folder in the store (healthy or damaged), sorted."""
    root = logged_root()
    if not root.is_dir():
        return []
    out = []
    for bdir in sorted(root.glob("*/*/*")):
        parts = bdir.relative_to(root).parts
        if not bdir.is_dir() or not all(SCENE_RE.fullmatch(p) for p in parts):
            continue
        try:
            lid = parse_logged_id("/".join(parts))
        except UnknownNameError:  # e.g. a variant folder that is not one
            continue
        if local_versions(lid, damaged=True):
            out.append(lid.name)
    return out


def id_of_dir(vdir: Path) -> LoggedId | None:
    """The id of a version folder in the store (None for one elsewhere, e.g. a download being checked)."""
    try:
        parts = vdir.resolve().relative_to(logged_root().resolve()).parts
        return parse_logged_id("/".join(parts[:3])) if len(parts) == 4 else None
    except (ValueError, UnknownNameError, OSError):
        return None


def clean_logged_stages() -> list[Path]:
    """Remove the staging folders under ``<root>/work`` that a killed log or pull left (none held by a live
    process); returns them. Every write does it first; ``python -m dtradar_rl log`` too."""
    work = P.data_root() / "work"
    return [p for prefix in STAGE_PREFIXES for p in clean_stale_stages(work, prefix, lockless=looks_like_stage)]


def logging_lock(lid: LoggedId, version: str):
    """A context manager held while one process logs ``lid@version`` (the rollout, then the write): a second
    process with the same settings says whom it waits for (:func:`~dtradar_data.core.files.waiting_lock`), waits,
    then finds the version stored."""
    return waiting_lock(
        logged_dir(lid) / f".{version}.logging.lock",
        f"logging {lid.name}@{version}",
        then="this process reuses that version",
    )


def _verified(vdir: Path, version: str) -> bool:
    """Whether the stored version folder holds the record and the file it should (the cheap checks)."""
    try:
        meta = read_meta(vdir)
        rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
        f = vdir / TRANSITIONS_FILE
        return meta.get("version") == version and f.is_file() and sha256_file(f) == rec.get("sha256")
    except (CorruptDatasetError, OSError):
        return False


def write_logged(
    name: str | LoggedId, inputs: dict[str, Any], table: pa.Table, meta: dict[str, Any]
) -> tuple[str, Path]:
    """Store a logged version atomically (reused when it exists) and tag it; returns ``(version, directory)``.

    ``meta`` is stored in ``meta.json`` with the name, version, inputs, table stats, file hashes and creation time
    added; the card is rendered from it. A stored copy of the version that is damaged (no readable ``meta.json``,
    or a file that no longer matches it) is replaced; stale staging folders of killed writers are removed."""
    lid = parse_logged_id(name).with_revision(None)
    check_transitions(table)
    version = logged_version(inputs)
    ddir = logged_dir(lid)
    ddir.mkdir(parents=True, exist_ok=True)
    clean_logged_stages()
    with waiting_lock(ddir / ".lock", f"storing a version of {lid.name}", notice_after_s=2.0):
        vdir = ddir / version
        refs = read_refs(refs_path(lid))
        if not (vdir.is_dir() and _verified(vdir, version)):
            with held_stage(P.work_root(), STAGE_PREFIXES[0], lockless=looks_like_stage) as stage:
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
                _replace(vdir, stage)
        if refs.tag_of(version) is None:
            refs = Refs({**refs.tags, refs.next_tag(): version}, version)
            write_refs(refs_path(lid), refs)
    return version, vdir


def _replace(vdir: Path, stage: Path) -> None:
    """Move ``stage`` to ``vdir``; a damaged folder there is first moved aside into a held folder under the work
    folder (same filesystem) and removed after, so a reader finds the old folder or the new one, never a mix."""
    if not vdir.exists():
        shutil.move(str(stage), vdir)
        return
    with held_stage(P.work_root(), STAGE_PREFIXES[0], lockless=looks_like_stage) as trash:
        os.rename(vdir, trash / vdir.name)
        shutil.move(str(stage), vdir)


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
    with waiting_lock(ddir / ".lock", f"installing a version of {lid.name}", notice_after_s=2.0):
        vdir = ddir / version
        if not (vdir.is_dir() and _verified(vdir, version)):  # absent or damaged: the verified download replaces it
            _replace(vdir, staged)
        refs = read_refs(refs_path(lid))
        if refs.tag_of(version) is None:
            tag = (
                preferred_tag
                if preferred_tag and is_tag(preferred_tag) and preferred_tag not in refs.tags
                else refs.next_tag()
            )
            write_refs(refs_path(lid), Refs({**refs.tags, tag: version}, version))
    return vdir


def _hint(vdir: Path, meta: dict[str, Any] | None = None) -> str:
    """How to get the version in ``vdir`` again (exact when ``meta`` says how it was logged)."""
    lid = id_of_dir(vdir)
    if lid is None:
        return "log or pull the dataset again (`python -m dtradar_rl log ...`)"
    return relog_hint(lid, meta, damaged=str(vdir))


def read_meta(vdir: Path) -> dict[str, Any]:
    """The ``meta.json`` of a logged version; :class:`CorruptDatasetError` naming the file when it is missing or is
    not a logged-dataset record."""
    path = vdir / P.META_FILE
    try:
        meta = json.loads(path.read_text())
        if not isinstance(meta, dict) or meta.get("format") != TRANSITIONS_FORMAT:
            raise ValueError(
                f"format {meta.get('format') if isinstance(meta, dict) else None!r}, expected {TRANSITIONS_FORMAT}"
            )
        return meta
    except FileNotFoundError as exc:
        raise CorruptDatasetError(f"{path} is missing", hint=_hint(vdir)) from exc
    except (OSError, ValueError) as exc:
        raise CorruptDatasetError(f"{path} is not a logged-dataset record ({exc})", hint=_hint(vdir)) from exc


def resolve_logged(
    name: str | LoggedId, revision: str | None = None, *, damaged: bool = False
) -> tuple[LoggedId, str, Path]:
    """``(id, version, folder)`` of a stored logged version (``damaged``: also one without ``meta.json``). A name
    not in the store is a :class:`DatasetNotFoundError` with the stored name it was probably meant to be, if any,
    and the command that logs it."""
    lid = parse_logged_id(name)
    revision = one_revision(lid.revision, revision)
    versions = local_versions(lid, damaged=damaged)
    if not versions:
        others = [n for n in logged_names() if n != lid.name]
        suggestion = did_you_mean(lid.name, others)
        raise DatasetNotFoundError(
            f"logged dataset {lid.name} is not in {logged_root()}" + (f"; {suggestion}" if suggestion else ""),
            hint=relog_hint(lid, new=True)
            + ("; `python -m dtradar_data list` shows the stored ones" if others else ""),
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
    ``verify`` re-hashes the file against ``meta.json``; the table is always checked (:func:`check_transitions`).
    A damaged version asked for (or the only ones there are) is a :class:`CorruptDatasetError` naming its file, not
    "not in the store"."""
    try:
        lid, version, vdir = resolve_logged(name, revision)
    except (DatasetNotFoundError, RevisionNotFoundError):
        lid, version, vdir = resolve_logged(name, revision, damaged=True)  # raises again when none is damaged
    meta = read_meta(vdir)
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file():
        raise CorruptDatasetError(f"{f} is missing", hint=_hint(vdir, meta))
    if verify and sha256_file(f) != rec.get("sha256"):
        raise CorruptDatasetError(f"{f}: sha256 differs from meta.json (changed or damaged)", hint=_hint(vdir, meta))
    try:
        table = read_transitions(f)
    except (CorruptDatasetError, SchemaMismatchError) as exc:
        raise type(exc)(exc.message, hint=_hint(vdir, meta)) from exc
    tag = read_refs(refs_path(lid)).tag_of(version)
    meta["tag"] = tag
    return LoggedDataset(lid.name, version, tag, table, meta, vdir)
