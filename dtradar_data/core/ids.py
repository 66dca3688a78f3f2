"""Dataset ids: ``<scene>/<variant>[@<revision>]``, one grammar with a parse/format pair.

Modelled on Minari (``namespace/name-v0``) and huggingface_hub (``repo@revision``):

* ``scene``    — ``[a-z0-9][a-z0-9_-]*``, e.g. ``cubicle``, ``meeting``, ``dallas-q3``;
* ``variant``  — ``blueprint`` (static objects) or ``dynamic`` (blueprint + movable objects);
* ``revision`` — optional: a tag ``v0``, ``v1``, ... or a version hash (hex, a prefix of at least 7 characters).

``parse_id`` checks the grammar and, given the ``known`` scenes, that the scene is one of them; unknown names fail with
a "did you mean ...?" built from the known ``scene/variant`` names. Which scenes are known (built-in ones and those
with data in the data root) is the store's business: :func:`dtradar_data.store.catalog.as_id`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from dtradar_data.core.errors import UnknownNameError, did_you_mean, unknown_name

VARIANTS: tuple[str, ...] = ("blueprint", "dynamic")

SCENE_RE = re.compile(r"[a-z0-9][a-z0-9_-]*")
TAG_RE = re.compile(r"v(0|[1-9][0-9]*)")
HASH_RE = re.compile(r"[0-9a-f]{7,64}")
MIN_HASH_PREFIX = 7
GRAMMAR = "<scene>/<variant>[@<revision>], e.g. 'cubicle/blueprint' or 'cubicle/dynamic@v0'"


@dataclass(frozen=True)
class DatasetId:
    """A parsed dataset id. ``revision`` is None for "the newest version"."""

    scene: str
    variant: str
    revision: str | None = None

    @property
    def name(self) -> str:
        """``scene/variant`` without the revision: the dataset, not one of its versions."""
        return f"{self.scene}/{self.variant}"

    def with_revision(self, revision: str | None) -> DatasetId:
        return DatasetId(self.scene, self.variant, revision)

    def __str__(self) -> str:
        return format_id(self)


def is_tag(revision: str) -> bool:
    return TAG_RE.fullmatch(revision) is not None


def is_hash(revision: str) -> bool:
    return HASH_RE.fullmatch(revision) is not None


def names_of(scenes: Iterable[str]) -> list[str]:
    """Every ``scene/variant`` name of the given scenes."""
    return [f"{s}/{v}" for s in sorted(set(scenes)) for v in VARIANTS]


def parse_id(text: str, *, known: Iterable[str] | None = None) -> DatasetId:
    """Parse ``scene/variant[@revision]``.

    ``known`` is the set of valid scenes; without it only the grammar is checked. Raises :class:`UnknownNameError`
    with a suggestion on a malformed id or an unknown scene or variant.
    """
    check_known = known is not None
    if not isinstance(text, str):
        raise UnknownNameError(f"dataset id must be a string, got {type(text).__name__}", hint=f"use {GRAMMAR}")
    raw = text.strip()
    name, sep, revision = raw.partition("@")
    scenes = sorted(set(known or ()))
    candidates = names_of(scenes)
    if sep and not revision:
        raise UnknownNameError(f"dataset id {text!r} has an empty revision after '@'",
                               hint="write a tag (v0, v1, ...) or a version hash after '@', or drop the '@'")
    if revision and not (is_tag(revision) or is_hash(revision)):
        raise UnknownNameError(
            f"revision {revision!r} in {text!r} is neither a tag nor a version hash",
            hint=f"use a tag like 'v0' or at least {MIN_HASH_PREFIX} lowercase hex characters of a version hash")
    parts = name.split("/")
    if len(parts) != 2 or not SCENE_RE.fullmatch(parts[0]) or not parts[1]:
        # "cubicle" alone is the most common slip: suggest both of its variants.
        guess = [c for c in candidates if c.startswith(f"{name.lower()}/")] or None
        suggestion = (f"did you mean {' or '.join(repr(g) for g in guess)}?" if guess
                      else did_you_mean(name.lower(), candidates))
        raise UnknownNameError(
            f"malformed dataset id {text!r}" + (f"; {suggestion}" if suggestion else ""), hint=f"use {GRAMMAR}")
    scene, variant = parts
    if variant not in VARIANTS or (check_known and scene not in scenes):
        raise unknown_name("dataset", name, candidates if check_known else [f"{scene}/{v}" for v in VARIANTS])
    return DatasetId(scene, variant, revision or None)


def format_id(dataset_id: DatasetId) -> str:
    """The inverse of :func:`parse_id`: ``parse_id(format_id(d)) == d``."""
    suffix = f"@{dataset_id.revision}" if dataset_id.revision else ""
    return f"{dataset_id.scene}/{dataset_id.variant}{suffix}"
