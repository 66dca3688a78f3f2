"""What the store holds: every dataset with its versions (listing), full verification, version history.

Logged datasets (``scene/variant/behaviour``) go through the same paths: :func:`verify` takes either form of the
id, and their listing is :func:`dtradar_data.store.logged.list_logged` (damaged versions flagged the same way)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dtradar_data.core import layout as P
from dtradar_data.core.errors import CorruptDatasetError, DatasetNotFoundError, RevisionNotFoundError
from dtradar_data.core.ids import DATASET_VARIANTS, DatasetId, LoggedId, is_logged_name
from dtradar_data.scenes import builtin_names
from dtradar_data.store.catalog import as_id, builtin_scenes
from dtradar_data.store.local import (
    history_metas,
    local_versions,
    read_meta,
    resolve,
    verify_dir,
)
from dtradar_data.store.logged import verify_logged
from dtradar_data.store.versions import read_refs
from dtradar_data.store.writers import being_written, check_not_being_written


@dataclass(frozen=True)
class VersionInfo:
    tag: str | None
    version: str
    created_utc: str | None
    num_rows: int | None
    size_bytes: int
    path: Path
    problem: str | None = None
    """Why the version is damaged (its ``meta.json`` missing or unreadable); None for a healthy one."""


@dataclass(frozen=True)
class DatasetEntry:
    """One ``scene/variant``: built-in (has a scene file) and/or stored (has versions)."""

    name: str
    scene: str
    variant: str
    builtin: bool
    versions: tuple[VersionInfo, ...]
    latest: str | None
    damaged: tuple[VersionInfo, ...] = ()
    """Version folders that cannot be read (see :func:`~dtradar_data.store.local.damaged_versions`)."""

    @property
    def built(self) -> bool:
        return bool(self.versions)


def version_infos(did: DatasetId) -> list[VersionInfo]:
    """The readable versions of ``did``, oldest first (:func:`all_version_infos` adds the damaged ones)."""
    return [v for v in all_version_infos(did) if v.problem is None]


def all_version_infos(did: DatasetId) -> list[VersionInfo]:
    """Every version folder of ``did``, oldest first; a damaged one has ``problem`` set instead of failing."""
    refs = read_refs(P.refs_path(did.scene, did.variant))
    out = []
    for v in local_versions(did, damaged=True):
        vdir = P.version_dir(did.scene, did.variant, v)
        try:
            meta = read_meta(vdir)
        except CorruptDatasetError as exc:
            out.append(
                VersionInfo(
                    tag=refs.tag_of(v),
                    version=v,
                    created_utc=None,
                    num_rows=None,
                    size_bytes=sum(f.stat().st_size for f in vdir.iterdir() if f.is_file()),
                    path=vdir,
                    problem=exc.message,
                )
            )
            continue
        files = meta.get("files") or {}
        out.append(
            VersionInfo(
                tag=refs.tag_of(v),
                version=v,
                created_utc=meta.get("created_utc"),
                num_rows=(meta.get("stats") or {}).get("num_cells", _grid_cells(meta)),
                size_bytes=sum(int(f.get("bytes", 0)) for f in files.values()),
                path=vdir,
            )
        )
    return out


def _grid_cells(meta: dict[str, Any]) -> int | None:
    g = meta.get("grid") or {}
    return int(g["nx"]) * int(g["ny"]) if "nx" in g and "ny" in g else None


def list_datasets() -> list[DatasetEntry]:
    """Every built-in ``scene/variant`` (built or not) and every stored one, sorted by name."""
    builtin = set(builtin_scenes())
    names = set(builtin_names())
    root = P.datasets_root()
    if root.is_dir():
        names |= {
            f"{s.name}/{v.name}"
            for s in root.iterdir()
            if s.is_dir()
            for v in s.iterdir()
            if v.is_dir() and v.name in DATASET_VARIANTS
        }
    rows = []
    for name in sorted(names):
        scene, variant = name.split("/")
        did = DatasetId(scene, variant)
        every = all_version_infos(did)
        infos = [v for v in every if v.problem is None]
        refs = read_refs(P.refs_path(scene, variant))
        latest = refs.latest if refs.latest in {i.version for i in infos} else (infos[-1].version if infos else None)
        rows.append(
            DatasetEntry(
                name,
                scene,
                variant,
                scene in builtin,
                tuple(infos),
                latest,
                tuple(v for v in every if v.problem is not None),
            )
        )
    return rows


def verify(name: str | DatasetId | LoggedId, revision: str | None = None) -> dict[str, list[str]]:
    """``{version: problems}`` for one version (``revision`` or ``@rev`` in ``name``) or, without one, all; an RT
    dataset or a logged one (:func:`~dtradar_data.store.logged.verify_logged`), damaged versions included.

    A version a live process is writing (:func:`~dtradar_data.store.writers.being_written`) is unfinished, not
    damaged: asked for by name, or when it leaves nothing else to verify, it is an
    :class:`~dtradar_data.core.errors.InUseError` naming that process; otherwise it is left out here (the ``verify``
    command lists it apart)."""
    try:
        results = _verify(name, revision)
    except (DatasetNotFoundError, RevisionNotFoundError):
        check_not_being_written(name, revision)  # not there yet: being built or logged right now
        raise
    busy = being_written(name) if any(results.values()) else {}  # asked after: a writer may have begun meanwhile
    unfinished = [v for v, problems in results.items() if problems and v in busy]
    for version in unfinished:
        del results[version]
    if unfinished and (revision or "@" in str(name) or not results):
        check_not_being_written(name, unfinished[0])
    return results


def _verify(name: str | DatasetId | LoggedId, revision: str | None) -> dict[str, list[str]]:
    if is_logged_name(name):
        return verify_logged(name, revision)
    did = as_id(name)
    # damaged=True: a version folder without meta.json is reported as damaged, not as "not built"
    if revision or did.revision:
        _, version, vdir = resolve(did, revision, damaged=True)
        return {version: verify_dir(vdir)}
    resolve(did, damaged=True)  # raises DatasetNotFoundError with the build hint when there is nothing
    return {v: verify_dir(P.version_dir(did.scene, did.variant, v)) for v in local_versions(did, damaged=True)}


def history(name: str | DatasetId) -> list[tuple[str, dict[str, Any]]]:
    did = as_id(name)
    return history_metas(did, read_refs(P.refs_path(did.scene, did.variant)))
