"""Which scene names belong to dtradar, so that a user's scene file can never take one.

A dataset is stored under its scene's name (``<scene>/<variant>``), so a user's room file whose ``[scene] name`` is
``cubicle`` would be stored as a new version of ``cubicle/blueprint``, and ``load("cubicle/blueprint")`` would return
the user's room. Reserved, for every scene file except the packaged one that defines the name:

* the built-in rooms (``cubicle``, ``meeting``: the files of :mod:`dtradar_data.scenes.indoor`);
* the built-in cities (``dallas``, ``houston``: :mod:`dtradar_data.scenes.city`) and their quadrants
  (``dallas-q1`` ... ``dallas-q4``);
* the namespace of Sionna's bundled scenes: every name starting with ``sionna-`` (``sionna-munich`` ...), which a
  build resolves to a bundled scene;
* the old names of renamed built-ins (``dallas-cells``, ``dallas-cells-q3``: :mod:`dtradar_data.core.renamed`),
  which still name them;
* the names of antenna-pose-error twins: every name ending in ``-txpose`` (``cubicle-txpose``).

:func:`check_user_scene_name` is called by every reader of a user's file as soon as the name is known, before any
mesh, footprint or ray is touched; the error says to rename the scene.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from dtradar_data.core.errors import SceneFileError
from dtradar_data.core.ids import TX_POSE_SUFFIX
from dtradar_data.core.renamed import RENAMED
from dtradar_data.scenes.sionna_scenes import is_sionna_name

__all__ = ["QUADRANTS", "builtin_scene_file", "check_user_scene_name", "reserved_because"]

#: The quadrants of a city (its datasets are ``<city>-q1`` ... ``<city>-q4``).
QUADRANTS = ("q1", "q2", "q3", "q4")
_INDOOR, _CITY = "dtradar_data.scenes.indoor", "dtradar_data.scenes.city"


def _packaged(package: str) -> dict[str, Path]:
    return {p.name[:-5]: Path(str(p)) for p in resources.files(package).iterdir() if p.name.endswith(".toml")}


def _split_quadrant(name: str) -> tuple[str, str] | None:
    city, sep, quadrant = name.rpartition("-")
    return (city, quadrant) if sep and quadrant in QUADRANTS and city in _packaged(_CITY) else None


def reserved_because(name: str) -> str | None:
    """Why ``name`` cannot be a user's scene name (whose it is), or None when it is free."""
    if name in _packaged(_INDOOR):
        return f"the name of the built-in room {name!r}"
    if name in _packaged(_CITY):
        return f"the name of the built-in city {name!r}"
    if (parts := _split_quadrant(name)) is not None:
        return f"the name of quadrant {parts[1]} of the built-in city {parts[0]!r}"
    if name in RENAMED:
        return f"the old name of the built-in {RENAMED[name]!r}, still taken as its alias"
    if is_sionna_name(name):
        return "in the namespace of Sionna's bundled scenes (sionna-...)"
    if name.endswith(TX_POSE_SUFFIX):
        return f"the name of an antenna-pose-error twin (names ending in {TX_POSE_SUFFIX!r})"
    return None


def builtin_scene_file(name: str) -> Path | None:
    """The packaged file that defines the built-in scene or city ``name``, or None."""
    return _packaged(_INDOOR).get(name) or _packaged(_CITY).get(name)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def check_user_scene_name(
    name: str,
    path: str | Path,
    *,
    derived: tuple[str, ...] = (),
    where: str = "[scene] name",
    rename: str | None = None,
) -> None:
    """:class:`SceneFileError` when the file ``path`` names its scene ``name`` (or makes a dataset scene in
    ``derived``, such as a city's quadrants) with a reserved name; the packaged file of a built-in may use its own.
    ``where`` says where the name comes from, ``rename`` how to change it (default: edit ``[scene] name``)."""
    own = builtin_scene_file(name)
    if own is not None and _same_file(Path(path).expanduser(), own):
        return
    for scene in (name, *derived):
        reason = reserved_because(scene)
        if reason is None:
            continue
        made = "" if scene == name else f" (it makes the scene {scene!r})"
        suggestion = "my-" + name.removeprefix("sionna-").removesuffix(TX_POSE_SUFFIX)
        raise SceneFileError(
            f"{path}: {where} {name!r}{made} is {reason}: reserved, so that a scene of yours is never stored or "
            "loaded as a built-in dataset",
            hint=rename or f'rename the scene in the file\'s [scene] section, e.g. name = "{suggestion}"',
        )
