"""Publish logged offline-RL datasets to, and pull them from, Hugging Face Hub dataset repos.

The same protocol as RT datasets (:mod:`dtradar_data.publish.hub`, whose error handling, offline switch, endpoint
and token lookup this reuses): one repo per ``scene/variant/behaviour`` (default
``dtradar/dtradar-<scene>-<variant>-<behaviour>``), one commit per version holding ``transitions.parquet``,
``meta.json`` and the card ``README.md`` (its ``configs`` point the Hub viewer and ``datasets.load_dataset`` at the
Parquet file), tagged with the local tag and the content version. A pull downloads into a temporary folder under
``<root>/work`` (held by its process: one that a killed pull left is removed by the next log or pull), checks the
record, the file's sha256, the table's invariants and that the version is the hash of the recorded logging inputs,
and only then moves it into the store (replacing a damaged copy of that version).
"""

from __future__ import annotations

import contextlib
import shutil
from pathlib import Path
from typing import Any

from dtradar_data.core import layout as P
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    DtradarError,
    RevisionNotFoundError,
)
from dtradar_data.core.ids import is_tag
from dtradar_data.publish import hub
from dtradar_data.store.logged import (
    STAGE_PREFIXES,
    TRANSITIONS_FILE,
    LoggedId,
    check_version_dir,
    clean_logged_stages,
    install_logged,
    local_versions,
    looks_like_stage,
    parse_logged_id,
    refs_path,
    relog_hint,
    resolve_logged,
)
from dtradar_data.store.logged.staging import held_stage
from dtradar_data.store.versions import read_refs

FILES = (TRANSITIONS_FILE, P.META_FILE, P.CARD_FILE)


def default_repo(lid: LoggedId) -> str:
    return f"dtradar/dtradar-{lid.scene}-{lid.variant}-{lid.behaviour}"


def publish(
    name: str | LoggedId,
    revision: str | None = None,
    *,
    repo_id: str | None = None,
    private: bool = False,
    api: Any = None,
) -> hub.PublishResult:
    """Upload one stored logged version (verified first) as one commit tagged with its tag and version."""
    from huggingface_hub import CommitOperationAdd

    if repo_id is not None:
        hub.check_repo_id(repo_id)
    lid, version, vdir = resolve_logged(name, revision)
    repo_id = repo_id or default_repo(lid)
    try:
        check_version_dir(vdir)
    except CorruptDatasetError as exc:
        raise CorruptDatasetError(
            f"refusing to publish damaged {lid.name}@{version}: {exc.message}", hint="log it again first"
        ) from exc
    tag = read_refs(refs_path(lid)).tag_of(version)
    ops = [CommitOperationAdd(path_in_repo=f, path_or_fileobj=str(vdir / f)) for f in FILES if (vdir / f).is_file()]
    return hub.push_version(
        repo_id, ops, name=lid.name, tag=tag, version=version, what="logged dataset", private=private, api=api
    )


def _download(repo_id: str, revision: str, dest: Path, cache: Path) -> Path:
    """A logged dataset's files (:func:`~dtradar_data.publish.hub.download`; tests replace it with a local folder)."""
    return hub.download(repo_id, revision, dest, cache, files=list(FILES))


def _without_the_hub(lid: LoggedId) -> str:
    """What a pull's user can do without the Hub: use the copy already here (named), or log it (the commands)."""
    try:
        _, version, vdir = resolve_logged(lid)
    except DtradarError:
        return relog_hint(lid, new=True)
    tag = read_refs(refs_path(lid)).tag_of(version)
    return f"use the copy already here: {lid.name}@{tag or version} ({vdir}) is its newest version in the local store"


def pull(name: str | LoggedId, revision: str | None = None, *, repo_id: str | None = None) -> Path:
    """Make ``name@revision`` available locally: return it if stored, else download, verify and install it."""
    return pull_version(name, revision, repo_id=repo_id).path


def pull_version(name: str | LoggedId, revision: str | None = None, *, repo_id: str | None = None) -> hub.PullResult:
    """:func:`pull`, saying what it did (:meth:`~dtradar_data.publish.hub.PullResult.describe`)."""
    if repo_id is not None:
        hub.check_repo_id(repo_id)
    lid = parse_logged_id(name)
    revision = revision or lid.revision
    lid, repo_id = lid.with_revision(None), repo_id or default_repo(lid)
    tag_of = read_refs(refs_path(lid)).tag_of
    if revision is not None:
        with contextlib.suppress(DatasetNotFoundError, RevisionNotFoundError):
            _, version, vdir = resolve_logged(lid, revision)
            return hub.PullResult(lid.name, vdir, version, tag_of(version), repo_id, revision, False, False)
    # held by this process: the next log or pull removes it if this one is killed (store.logged.staging)
    clean_logged_stages()
    instead = _without_the_hub(lid)
    with held_stage(P.work_root(), STAGE_PREFIXES[1], lockless=looks_like_stage) as stage:
        with hub.hub_errors("pull from", repo_id, what=revision and f"{lid.name}@{revision}", instead=instead):
            got = _download(repo_id, revision or "main", stage / "download", stage / "cache")
        version_dir = stage / "version"
        version_dir.mkdir()
        for f in FILES:
            if (got / f).is_file():
                shutil.move(str(got / f), version_dir / f)
        try:
            check_version_dir(version_dir)
        except CorruptDatasetError as exc:
            raise CorruptDatasetError(
                f"the download of {lid.name} from {repo_id!r} failed verification: {exc.message}",
                hint="retry; if it persists the Hub copy is damaged",
            ) from exc
        existed = set(local_versions(lid))
        preferred = revision if revision and is_tag(revision) else hub._card_tag(version_dir / P.CARD_FILE)
        path = install_logged(lid, version_dir, preferred_tag=preferred)
    tag = read_refs(refs_path(lid)).tag_of(path.name)
    return hub.PullResult(lid.name, path, path.name, tag, repo_id, revision, True, path.name not in existed)


__all__ = ["FILES", "default_repo", "publish", "pull", "pull_version"]
