"""Which datasets exist: the built-in scenes plus every scene with data in the data root, and ids checked against them.

Every public function of the store takes a name as text or as a parsed :class:`~dtradar_data.core.ids.DatasetId`;
:func:`as_id` turns text into an id, with a "did you mean ...?" over the names that exist here (:func:`known_names`:
each built-in scene's real variants, and every one stored), never over a combination no build makes
(``sionna-munich/dynamic``). :func:`missing_twin` is the error for a built-in scene's variant that does not exist,
:func:`build_command` the command that builds one that does.
"""

from __future__ import annotations

from dtradar_data.core import layout
from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.ids import (
    DATASET_VARIANTS,
    MOVING_VARIANT,
    SCENE_RE,
    TX_POSE_SUFFIX,
    DatasetId,
    LoggedId,
    is_logged_name,
    parse_id,
    parse_name,
)
from dtradar_data.core.renamed import stored_or_current
from dtradar_data.scenes import available_scenes, builtin_moving_names, builtin_names


def builtin_scenes() -> list[str]:
    """Scenes that ship with the package (a scene file each)."""
    return list(available_scenes())


def stored_scenes() -> list[str]:
    """Scenes that have at least one dataset directory in the data root (built from a user file, or pulled)."""
    root = layout.datasets_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if p.is_dir() and SCENE_RE.fullmatch(p.name))


def stored_names() -> list[str]:
    """Every ``scene/variant`` with a dataset folder in the data root (built, pulled, or damaged)."""
    return sorted(
        f"{scene}/{v.name}"
        for scene in stored_scenes()
        for v in (layout.datasets_root() / scene).iterdir()
        if v.is_dir() and v.name in DATASET_VARIANTS
    )


def known_scenes() -> list[str]:
    return sorted(set(builtin_scenes()) | set(stored_scenes()))


def known_names() -> list[str]:
    """Every ``scene/variant`` name that exists here: the variants each built-in scene's file makes (its blueprint,
    its dynamic and moving twins where it has them) and every one in the data root."""
    return sorted({*builtin_names(), *builtin_moving_names(), *stored_names()})


def renamed(text: str) -> str:
    """``text`` (a dataset or logged dataset name) with a renamed scene (:mod:`dtradar_data.core.renamed`) spelt as
    the store holds it: the current name, or the old one where only the old name's data is stored."""
    if not isinstance(text, str):
        return text  # parse_id names the wrong type
    scene, sep, rest = text.strip().partition("/")
    roots = (layout.datasets_root(), layout.data_root() / "logged")
    return stored_or_current(scene, lambda s: any((r / s).is_dir() for r in roots)) + sep + rest


def missing_twin(did: DatasetId) -> DatasetNotFoundError | None:
    """The error for a variant a built-in scene does not have and the store does not hold (``dallas-q1/dynamic``:
    its city file makes no dynamic twin of that quadrant, so no build or pull of it can succeed): it names the
    datasets the scene has instead of a build that would refuse. None for every other name (a user's scene may
    gain any variant, by a build from its file or a pull)."""
    if did.scene not in builtin_scenes():
        return None
    names = known_names()
    if did.name in names:
        return None
    own = [n for n in names if n.startswith(f"{did.scene}/")]
    others = [n for n in names if n.endswith(f"/{did.variant}")]
    return DatasetNotFoundError(
        f"{did.scene} has no {did.variant} twin, so {did.name} cannot be built or pulled; "
        f"its datasets are {', '.join(own)}",
        hint=f"use {' or '.join(own)}"
        + (f", or another scene's {did.variant} twin: {', '.join(others)}" if others else ""),
    )


def build_command(did: DatasetId) -> str:
    """The command that builds ``did``, in backquotes, its scene filled in: ``make dataset`` for a built-in scene; a
    user's scene (or its antenna-pose twin) is built from the scene file it came from, which ``make dataset`` with
    the bare name could not find."""
    scene, variant = did.scene, did.variant
    base = scene.removesuffix(TX_POSE_SUFFIX)
    pose = " --tx-pose-error OFFSET_M ANGLE_DEG" if scene.endswith(TX_POSE_SUFFIX) else ""
    if scene in builtin_scenes():
        make = f"`make dataset SCENE={scene}" + (f" VARIANT={variant}" if variant == MOVING_VARIANT else "") + "`"
        return f"{make} (or `python -m dtradar_data build --scene {scene} --variant {variant}`)"
    source = base if base in builtin_scenes() else f"path/to/{base}.toml"
    where = "" if base in builtin_scenes() else f" ({source}: {base}'s own scene file)"
    return f"`python -m dtradar_data build --scene {source} --variant {variant}{pose}`{where}"


def as_id(name: str | DatasetId, *, check_known: bool = True) -> DatasetId:
    """Accept either a string or an already parsed id (public functions take both)."""
    if isinstance(name, DatasetId):
        return name
    name = renamed(name)
    if not check_known:
        return parse_id(name)
    return parse_id(name, known=known_scenes(), names=known_names())


def as_any_id(name: str | DatasetId | LoggedId, *, check_known: bool = True) -> DatasetId | LoggedId:
    """Either form of the grammar (:func:`~dtradar_data.core.ids.parse_name`): an RT id, its scene checked against
    the known ones, or a logged id (any parent: logged datasets may sit on synthetic twins; a name that is not
    stored gets its "did you mean" from the logged store when it is resolved)."""
    if isinstance(name, (DatasetId, LoggedId)):
        return name
    name = renamed(name)
    if not check_known or is_logged_name(name):
        return parse_name(name)
    return parse_name(name, known=known_scenes(), names=known_names())
