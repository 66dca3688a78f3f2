"""Content-addressed dataset versions and the human tags that point at them.

A version is the 16-hex-character sha256 prefix of the canonical JSON of everything that determines a dataset's
content: the scene description, the ray-tracing settings, the schema version and the library versions. Building the
same inputs twice therefore yields the same version (the store reuses it); changing anything yields a new one.

Tags (``v0``, ``v1``, ...) are assigned in build order per ``scene/variant`` and recorded in ``refs.json``; a tag is
never moved to another version. "Latest" is the most recently *created* version (the highest tag): rebuilding an
older configuration reuses its version but does not make it the newest, so ``load(name)`` does not flip between
versions depending on the last command run. Pin with a tag or a hash to get a specific one.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

from dtradar_data.core.errors import CorruptDatasetError, RevisionNotFoundError
from dtradar_data.core.files import write_atomic
from dtradar_data.core.ids import MIN_HASH_PREFIX, TAG_RE, is_hash, is_tag

VERSION_CHARS = 16
#: Distributions whose versions change the numbers in a dataset (the ray tracer stack) or its files (pyarrow).
CONTENT_LIBRARIES: tuple[str, ...] = ("dtradar", "sionna-rt", "mitsuba", "drjit", "trimesh", "numpy", "pyarrow")


def _check_finite(obj: Any, where: str = "inputs") -> None:
    # NaN/inf have no JSON spelling that round-trips; a hash over them would depend on the encoder.
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"{where} holds a non-finite float {obj!r}; version inputs must be finite")
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_finite(v, f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _check_finite(v, f"{where}[{i}]")


def canonical_json(obj: Any) -> str:
    """Sorted keys, no whitespace, ASCII only: one spelling per value, so equal inputs hash equally."""
    _check_finite(obj)
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)


def version_id(inputs: dict[str, Any]) -> str:
    """The version of a dataset built from ``inputs`` (scene spec, RT settings, schema version, library versions)."""
    return hashlib.sha256(canonical_json(inputs).encode()).hexdigest()[:VERSION_CHARS]


def library_versions(names: tuple[str, ...] = CONTENT_LIBRARIES) -> dict[str, str]:
    """Installed versions of ``names`` (from package metadata: nothing is imported, so Sionna is not loaded)."""
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def build_inputs(
    scene_spec: dict[str, Any], rt: dict[str, Any], schema_version: int, libraries: dict[str, str] | None = None
) -> dict[str, Any]:
    """The dict :func:`version_id` hashes, in the shape the pipeline and the card both expect."""
    return {
        "scene_spec": scene_spec,
        "rt": rt,
        "schema_version": int(schema_version),
        "library_versions": library_versions() if libraries is None else dict(libraries),
    }


def tag_number(tag: str) -> int:
    m = TAG_RE.fullmatch(tag)
    if not m:
        raise ValueError(f"not a tag: {tag!r}")
    return int(m.group(1))


@dataclass
class Refs:
    """The content of ``refs.json``: tag -> version, and the newest version."""

    tags: dict[str, str] = field(default_factory=dict)
    latest: str | None = None

    def tag_of(self, version: str) -> str | None:
        return next((t for t, v in self.tags.items() if v == version), None)

    def next_tag(self) -> str:
        return f"v{max((tag_number(t) for t in self.tags), default=-1) + 1}"

    def ordered(self) -> list[tuple[str, str]]:
        """``(tag, version)`` pairs, oldest first."""
        return sorted(self.tags.items(), key=lambda kv: tag_number(kv[0]))

    def to_json(self) -> str:
        tags = dict(self.ordered())
        return json.dumps({"tags": tags, "latest": self.latest}, indent=2) + "\n"


def read_refs(path: Path) -> Refs:
    """Read ``refs.json``; a missing file is an empty dataset, a garbled one is a :class:`CorruptDatasetError`."""
    if not path.exists():
        return Refs()
    try:
        raw = json.loads(path.read_text())
        tags = {str(k): str(v) for k, v in raw["tags"].items()}
        latest = raw.get("latest")
        if any(not is_tag(t) for t in tags) or (latest is not None and latest not in tags.values()):
            raise ValueError("tags or latest are malformed")
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise CorruptDatasetError(
            f"{path} is not a valid refs file ({exc})",
            hint="delete it and re-run the build (versions on disk are kept and re-tagged), or re-pull",
        ) from exc
    return Refs(tags, latest)


def write_refs(path: Path, refs: Refs) -> None:
    write_atomic(path, refs.to_json())


def one_revision(in_name: str | None, given: str | None) -> str | None:
    """The revision asked for, given once: in the name (``@rev``) or as the argument. Both and different is a
    :class:`RevisionNotFoundError`; the same for an RT dataset and a logged one."""
    if given and in_name and given != in_name:
        raise RevisionNotFoundError(
            f"two revisions given: {in_name!r} in the name and {given!r}", hint="give the revision once"
        )
    return given or in_name


def resolve_revision(refs: Refs, versions: list[str], revision: str | None, name: str) -> str:
    """Turn ``revision`` (None = latest, a tag, a full hash or a unique prefix) into a version on disk.

    ``versions`` are the version directories that exist; refs may point at one that was deleted by hand.
    """
    existing = _listing(refs, versions)
    if revision is None:
        if refs.latest in versions:
            return refs.latest
        if versions:  # refs.json lost or stale: fall back to the most recently modified directory's order
            return versions[-1]
        raise RevisionNotFoundError(f"{name} has no versions", hint="build it or pull it")
    if is_tag(revision):
        version = refs.tags.get(revision)
        if version is None or version not in versions:
            raise RevisionNotFoundError(
                f"{name} has no version tagged {revision!r}; it has {existing}",
                hint=f"use one of those, e.g. {name}@{_example(refs, versions)}",
            )
        return version
    if is_hash(revision) and len(revision) >= MIN_HASH_PREFIX:
        matches = [v for v in versions if v.startswith(revision)]
        if len(matches) == 1:
            return matches[0]
        if len(matches) > 1:
            raise RevisionNotFoundError(
                f"{revision!r} matches several versions of {name}: {', '.join(matches)}",
                hint="give more characters of the hash",
            )
    raise RevisionNotFoundError(
        f"{name} has no version {revision!r}; it has {existing}",
        hint=f"use a tag or a hash prefix, e.g. {name}@{_example(refs, versions)}",
    )


def _listing(refs: Refs, versions: list[str]) -> str:
    if not versions:
        return "no versions"
    tagged = [f"{t} = {v}" for t, v in refs.ordered() if v in versions]
    untagged = [v for v in versions if refs.tag_of(v) is None]
    return ", ".join(tagged + untagged)


def _example(refs: Refs, versions: list[str]) -> str:
    for t, v in reversed(refs.ordered()):
        if v in versions:
            return t
    return versions[-1][:MIN_HASH_PREFIX] if versions else "v0"
