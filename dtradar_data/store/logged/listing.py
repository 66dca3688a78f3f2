"""What the logged store holds: every logged version (listing) and full verification."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError, UnknownNameError
from dtradar_data.core.ids import SCENE_RE, LoggedId, parse_logged_id
from dtradar_data.store.logged.local import (
    load_logged,
    local_versions,
    logged_root,
    read_meta,
    refs_path,
    resolve_logged,
)
from dtradar_data.store.versions import read_refs

__all__ = ["LoggedEntry", "verify_logged", "list_logged"]


def verify_logged(name: str | LoggedId, revision: str | None = None) -> dict[str, list[str]]:
    """``{version: problems}`` for one version or, without a revision, every version (empty list = fine)."""
    lid = parse_logged_id(name)
    if revision or lid.revision:
        versions = [resolve_logged(lid, revision)[1]]
    else:
        resolve_logged(lid)
        versions = local_versions(lid)
    out = {}
    for v in versions:
        problems = []
        try:
            load_logged(lid.with_revision(None), v)
        except (CorruptDatasetError, SchemaMismatchError) as exc:
            problems.append(exc.message)
        out[v] = problems
    return out


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


def list_logged() -> list[LoggedEntry]:
    """Every stored logged version, by name then tag."""
    root = logged_root()
    out = []
    if not root.is_dir():
        return out
    for bdir in sorted(root.glob("*/*/*")):
        if not bdir.is_dir() or not all(SCENE_RE.fullmatch(p) for p in bdir.relative_to(root).parts):
            continue
        try:
            lid = parse_logged_id("/".join(bdir.relative_to(root).parts))
        except UnknownNameError:
            continue
        refs = read_refs(refs_path(lid))
        for v in local_versions(lid):
            try:
                meta = read_meta(bdir / v)
            except CorruptDatasetError:
                meta = {}
            s = meta.get("stats") or {}
            out.append(
                LoggedEntry(
                    lid.name,
                    v,
                    refs.tag_of(v),
                    s.get("steps"),
                    s.get("episodes"),
                    s.get("success_rate"),
                    meta.get("parent", lid.parent),
                    bdir / v,
                )
            )
    return out
