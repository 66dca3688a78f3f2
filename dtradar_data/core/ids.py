"""Dataset ids: one grammar, two forms, each with a parse/format pair.

* an RT dataset: ``<scene>/<variant>[@<revision>]``, e.g. ``cubicle/blueprint@v0`` (:func:`parse_id`,
  :func:`format_id`);
* a logged (offline-RL) dataset: ``<scene>/<variant>/<behaviour>[@<revision>]``, e.g.
  ``cubicle/blueprint/noisy-shortest`` or ``cubicle/moving/expert``: the parent RT dataset (any variant, the moving
  twin's too) the transitions were logged on, then the behaviour's
  name (``[a-z0-9][a-z0-9_-]*``; by default the behaviour policy's kind) (:func:`parse_logged_id`,
  :func:`format_logged_id`). Two slashes tell it from an RT dataset (one slash), so :func:`dtradar_data.load`
  and the ``list``/``info``/``verify`` commands accept both (:func:`is_logged_name`; :func:`parse_name` and
  :func:`format_name` are the pair for either form).

Modelled on Minari (``namespace/name-v0``) and huggingface_hub (``repo@revision``):

* ``scene``    — ``[a-z0-9][a-z0-9_-]*``, e.g. ``cubicle``, ``meeting``, ``dallas-q3``; a name ending in ``-txpose``
  is an antenna-pose-error twin of the scene before it (``cubicle-txpose``), never a scene file's name;
* ``variant``  — ``blueprint`` (static objects), ``dynamic`` (blueprint + movable objects) or ``moving`` (people
  and vehicles moving through it: one table of snapshots in time, :data:`MOVING_VARIANT`);
* ``revision`` — optional: a tag ``v0``, ``v1``, ... or a version hash (hex, a prefix of at least 7 characters);
  without one, the newest version.

``parse_id`` checks the grammar and, given the ``known`` scenes, that the scene is one of them; unknown names fail with
a "did you mean ...?" built from the ``scene/variant`` names that exist (each scene's real variants, never a
combination no build makes). Which scenes and names are known (built-in ones and those with data in the data root) is
the store's business: :func:`dtradar_data.store.catalog.as_id`, :func:`~dtradar_data.store.catalog.known_names`.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from dtradar_data.core.errors import UnknownNameError, did_you_mean, unknown_name

#: The static twins' variants: what ``--variant all`` builds.
VARIANTS: tuple[str, ...] = ("blueprint", "dynamic")
#: The moving twin (``cubicle/moving``): snapshots in time in one table (:mod:`dtradar_data.core.dataset`), built
#: by ``build --variant moving`` (:mod:`dtradar_data.pipeline.moving`) only, never by ``--variant all``.
MOVING_VARIANT = "moving"
#: Every variant a stored RT dataset may have, and so every variant a logged dataset may sit on (a moving twin's log
#: is rolled out among its movers: :mod:`dtradar_rl.offline.moving_logs`).
DATASET_VARIANTS: tuple[str, ...] = (*VARIANTS, MOVING_VARIANT)
#: The suffix of an antenna-pose-error twin's scene (``cubicle-txpose``: :mod:`dtradar_data.scenes.tx_pose`). Scene
#: files may not use it, so such a twin never shares a name with a built-in or a user's scene.
TX_POSE_SUFFIX = "-txpose"

SCENE_RE = re.compile(r"[a-z0-9][a-z0-9_-]*")
TAG_RE = re.compile(r"v(0|[1-9][0-9]*)")
HASH_RE = re.compile(r"[0-9a-f]{7,64}")
MIN_HASH_PREFIX = 7
GRAMMAR = "<scene>/<variant>[@<revision>], e.g. 'cubicle/blueprint' or 'cubicle/dynamic@v0'"
LOGGED_GRAMMAR = "<scene>/<variant>/<behaviour>[@<revision>], e.g. 'cubicle/blueprint/noisy-shortest'"


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


def _split_revision(text: str, what: str) -> tuple[str, str | None]:
    """``name@revision`` -> ``(name, revision or None)``, the revision checked (both forms share it)."""
    name, sep, revision = text.strip().partition("@")
    if sep and not revision:
        raise UnknownNameError(
            f"{what} {text!r} has an empty revision after '@'",
            hint="write a tag (v0, v1, ...) or a version hash after '@', or drop the '@'",
        )
    if revision and not (is_tag(revision) or is_hash(revision)):
        raise UnknownNameError(
            f"revision {revision!r} in {text!r} is neither a tag nor a version hash",
            hint=f"use a tag like 'v0' or at least {MIN_HASH_PREFIX} lowercase hex characters of a version hash",
        )
    return name, revision or None


def parse_id(text: str, *, known: Iterable[str] | None = None, names: Iterable[str] | None = None) -> DatasetId:
    """Parse ``scene/variant[@revision]``.

    ``known`` is the set of valid scenes; without it only the grammar is checked. ``names`` are the ``scene/variant``
    names that exist (:func:`dtradar_data.store.catalog.known_names`: a scene's real variants), the only ones a "did
    you mean" suggests; without them, every variant of each known scene. Raises :class:`UnknownNameError` with a
    suggestion on a malformed id or an unknown scene or variant.
    """
    check_known = known is not None
    if not isinstance(text, str):
        raise UnknownNameError(f"dataset id must be a string, got {type(text).__name__}", hint=f"use {GRAMMAR}")
    name, revision = _split_revision(text, "dataset id")
    scenes = sorted(set(known or ()))
    candidates = sorted(set(names)) if names is not None else names_of(scenes)
    parts = name.split("/")
    if len(parts) == 3 and all(SCENE_RE.fullmatch(p) for p in parts):
        raise UnknownNameError(
            f"{text!r} is a logged dataset id ({LOGGED_GRAMMAR}), not an RT dataset id",
            hint=f"use {GRAMMAR} here, or open it as a logged dataset (dtradar_data.load, or parse_name)",
        )
    if len(parts) != 2 or not SCENE_RE.fullmatch(parts[0]) or not parts[1]:
        # "cubicle" alone is the most common slip: suggest both of its variants.
        guess = [c for c in candidates if c.startswith(f"{name.lower()}/")] or None
        suggestion = (
            f"did you mean {' or '.join(repr(g) for g in guess)}?" if guess else did_you_mean(name.lower(), candidates)
        )
        raise UnknownNameError(
            f"malformed dataset id {text!r}" + (f"; {suggestion}" if suggestion else ""), hint=f"use {GRAMMAR}"
        )
    scene, variant = parts
    own = [c for c in candidates if c.startswith(f"{scene}/")]
    if check_known and own and variant not in DATASET_VARIANTS:
        raise _unknown_variant(name, own)
    if variant not in DATASET_VARIANTS or (check_known and scene not in scenes):
        raise unknown_name("dataset", name, candidates if check_known else [f"{scene}/{v}" for v in DATASET_VARIANTS])
    return DatasetId(scene, variant, revision)


def _unknown_variant(name: str, own: list[str]) -> UnknownNameError:
    """A known scene with a misspelled variant: the suggestion is the closest of the datasets it has (``own``)."""
    by_variant = {c.partition("/")[2]: c for c in own}
    close = difflib.get_close_matches(name.partition("/")[2], list(by_variant), n=3, cutoff=0.5)
    suggestion = f"; did you mean {' or '.join(repr(by_variant[v]) for v in close)}?" if close else ""
    return UnknownNameError(f"unknown dataset {name!r}{suggestion}", hint=f"use one of: {', '.join(own)}")


def format_id(dataset_id: DatasetId) -> str:
    """The inverse of :func:`parse_id`: ``parse_id(format_id(d)) == d``."""
    suffix = f"@{dataset_id.revision}" if dataset_id.revision else ""
    return f"{dataset_id.scene}/{dataset_id.variant}{suffix}"


# ------------------------------------------------------------------------------------------- logged datasets
@dataclass(frozen=True)
class LoggedId:
    """A parsed logged-dataset id; ``revision`` None means the newest version."""

    scene: str
    variant: str
    behaviour: str
    revision: str | None = None

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.variant}/{self.behaviour}"

    @property
    def parent(self) -> str:
        """The RT dataset the transitions were logged on."""
        return f"{self.scene}/{self.variant}"

    def with_revision(self, revision: str | None) -> LoggedId:
        return LoggedId(self.scene, self.variant, self.behaviour, revision)

    def __str__(self) -> str:
        return format_logged_id(self)


def is_logged_name(text: Any) -> bool:
    """Whether ``text`` has the shape of a logged-dataset id (three ``/``-separated parts before any ``@``)."""
    return isinstance(text, (str, LoggedId)) and (isinstance(text, LoggedId) or text.partition("@")[0].count("/") == 2)


def parse_logged_id(text: str | LoggedId) -> LoggedId:
    """Parse ``scene/variant/behaviour[@revision]``; :class:`UnknownNameError` with the grammar otherwise."""
    if isinstance(text, LoggedId):
        return text
    if not isinstance(text, str):
        raise UnknownNameError(
            f"logged dataset id must be a string, got {type(text).__name__}", hint=f"use {LOGGED_GRAMMAR}"
        )
    name, revision = _split_revision(text, "logged dataset id")
    parts = name.split("/")
    if len(parts) != 3 or not all(SCENE_RE.fullmatch(p) for p in parts):
        raise UnknownNameError(
            f"malformed logged dataset id {text!r}", hint=f"use {LOGGED_GRAMMAR} (an RT dataset is {GRAMMAR})"
        )
    scene, variant, behaviour = parts
    if variant not in DATASET_VARIANTS:
        suggestion = did_you_mean(variant, DATASET_VARIANTS)
        raise UnknownNameError(
            f"unknown variant {variant!r} in {text!r}" + (f"; {suggestion}" if suggestion else ""),
            hint=f"use one of: {', '.join(DATASET_VARIANTS)}",
        )
    return LoggedId(scene, variant, behaviour, revision)


def format_logged_id(lid: LoggedId) -> str:
    """The inverse of :func:`parse_logged_id`."""
    return lid.name + (f"@{lid.revision}" if lid.revision else "")


# ------------------------------------------------------------------------------------------------- either form
def parse_name(
    text: str | DatasetId | LoggedId, *, known: Iterable[str] | None = None, names: Iterable[str] | None = None
) -> DatasetId | LoggedId:
    """Either form of the grammar: a logged id when the name has two slashes (:func:`parse_logged_id`), else an RT
    id (:func:`parse_id`, checked against the ``known`` scenes, suggesting among ``names``, when given). Parsed ids
    pass through."""
    if isinstance(text, (DatasetId, LoggedId)):
        return text
    return parse_logged_id(text) if is_logged_name(text) else parse_id(text, known=known, names=names)


def format_name(dataset_id: DatasetId | LoggedId) -> str:
    """The inverse of :func:`parse_name`: ``parse_name(format_name(i)) == i`` for either form."""
    return format_logged_id(dataset_id) if isinstance(dataset_id, LoggedId) else format_id(dataset_id)
