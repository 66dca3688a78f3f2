"""What the logged store holds: every logged version, damaged ones flagged (listing), and full verification."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dtradar_data.core import layout as P
from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError
from dtradar_data.core.files import sha256_file
from dtradar_data.core.ids import LoggedId, parse_logged_id
from dtradar_data.store.logged.local import (
    local_versions,
    logged_dir,
    logged_names,
    read_meta,
    read_transitions,
    refs_path,
    resolve_logged,
)
from dtradar_data.store.logged.table import TRANSITIONS_FILE
from dtradar_data.store.logged.versions import logged_version
from dtradar_data.store.versions import read_refs

__all__ = ["LoggedEntry", "verify_logged", "verify_logged_dir", "list_logged"]


def verify_logged_dir(lid: LoggedId, vdir: Path) -> list[str]:
    """Problems of one stored version folder (empty = fine), each naming its file: ``meta.json`` missing or not a
    record, a record of another name or version, a version that is not the hash of its logging inputs, the
    transitions file missing, of another size or sha256, or not a valid transition table."""
    try:
        meta = read_meta(vdir)
    except CorruptDatasetError as exc:
        return [exc.message]
    problems = []
    if meta.get("name") != lid.name or meta.get("version") != vdir.name:
        problems.append(
            f"{vdir / P.META_FILE} describes {meta.get('name')!r}@{meta.get('version')!r}, not {lid.name}@{vdir.name}"
        )
    inputs = meta.get("inputs")
    if not isinstance(inputs, dict) or logged_version(inputs) != vdir.name:
        problems.append(f"{vdir / P.META_FILE}: version {vdir.name} is not the hash of its logging inputs (edited?)")
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file():
        return [*problems, f"{f} is missing"]
    if f.stat().st_size != rec.get("bytes", f.stat().st_size) or sha256_file(f) != rec.get("sha256"):
        problems.append(f"{f}: sha256 differs from meta.json (changed or damaged)")
    try:
        read_transitions(f)
    except (CorruptDatasetError, SchemaMismatchError) as exc:
        problems.append(exc.message)
    return problems


def verify_logged(name: str | LoggedId, revision: str | None = None) -> dict[str, list[str]]:
    """``{version: problems}`` for one version or, without a revision, every version, damaged ones (no
    ``meta.json``) included (empty list = fine). A name with no version folder at all is a
    :class:`DatasetNotFoundError` (with a "did you mean" when a stored name is close)."""
    lid = parse_logged_id(name)
    if revision or lid.revision:
        _, version, _ = resolve_logged(lid, revision, damaged=True)
        versions = [version]
    else:
        resolve_logged(lid, damaged=True)
        versions = local_versions(lid, damaged=True)
    base = lid.with_revision(None)
    return {v: verify_logged_dir(base, logged_dir(base) / v) for v in versions}


@dataclass(frozen=True)
class LoggedEntry:
    name: str
    version: str
    tag: str | None
    steps: int | None
    episodes: int | None
    success_rate: float | None
    parent: str
    path: Path
    problem: str | None = None
    """Why the version is damaged (its ``meta.json`` missing or unreadable); None for a healthy one."""
    created_utc: str | None = None
    size_bytes: int | None = None


def list_logged(*, damaged: bool = True) -> list[LoggedEntry]:
    """Every stored logged version, by name then tag; a version folder whose ``meta.json`` is missing or unreadable
    is listed with its ``problem`` (``damaged=False`` leaves those out)."""
    out = []
    for name in logged_names():
        lid = parse_logged_id(name)
        refs = read_refs(refs_path(lid))
        for v in local_versions(lid, damaged=True):
            vdir = logged_dir(lid) / v
            problem = None
            try:
                meta = read_meta(vdir)
            except CorruptDatasetError as exc:
                meta, problem = {}, exc.message
                if not damaged:
                    continue
            s = meta.get("stats") or {}
            rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
            out.append(
                LoggedEntry(
                    lid.name,
                    v,
                    refs.tag_of(v),
                    s.get("steps"),
                    s.get("episodes"),
                    s.get("success_rate"),
                    meta.get("parent", lid.parent),
                    vdir,
                    problem,
                    meta.get("created_utc"),
                    rec.get("bytes"),
                )
            )
    return out
