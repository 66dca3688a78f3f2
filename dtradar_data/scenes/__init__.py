"""Scenes: the scene model, its materials, and the catalogue of scenes a user can name.

A scene is named by a built-in name (``cubicle``, ``meeting``: TOML files in :mod:`dtradar_data.scenes.indoor`; the
city quadrants ``dallas-q1`` ... ``houston-q4``: one TOML file per city in :mod:`dtradar_data.scenes.city`) or by the
path of the user's own scene file (``make dataset SCENE=path/to/room.toml``). A build may also name a whole city
(``dallas``): :func:`build_targets` expands it to its quadrants. Scenes built on a Mitsuba/Sionna XML
(:mod:`dtradar_data.scenes.xml_scene`): Sionna's bundled cities (``sionna:munich``, dataset ``sionna-munich``), a
user's ``.xml`` with ``--grid`` and ``--tx``, or a scene file with an ``[xml]`` section. :func:`tx_pose_error` makes
the antenna-pose-error twin of any of them (``<scene>-txpose``: the transmitter moved and turned a little).
:func:`load_moving_scene` reads a room's or a city quadrant's *moving* twin (people and vehicles moving through its
blueprint: :mod:`dtradar_data.scenes.moving_scene`), a series of static scenes that ``build --variant moving`` traces
(:mod:`dtradar_data.pipeline.moving`). A user's
scene file may not take a built-in name (:mod:`dtradar_data.scenes.names`), and the options that replace part of a
scene are checked before any file is read (:mod:`dtradar_data.scenes.options`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from dtradar_data.core.errors import InvalidSettingError, SceneFileError, unknown_name
from dtradar_data.core.ids import VARIANTS
from dtradar_data.core.renamed import current_scene
from dtradar_data.scenes.city.document import read_city_file
from dtradar_data.scenes.city.reader import (
    city_file,
    city_names,
    load_city_moving,
    load_city_spec,
    quadrant_scenes,
)
from dtradar_data.scenes.indoor.reader import declares_moving, load_moving_room_file, load_room_file
from dtradar_data.scenes.model import SceneSpec
from dtradar_data.scenes.mover import Mover
from dtradar_data.scenes.moving_scene import MOVING_VARIANT, MoverChange, MovingScene
from dtradar_data.scenes.names import check_user_scene_name
from dtradar_data.scenes.options import check_scene_options
from dtradar_data.scenes.sionna_scenes import is_sionna_name, sionna_dataset_scenes, sionna_scene_names
from dtradar_data.scenes.tx_pose import tx_pose_error
from dtradar_data.scenes.xml_scene import is_mesh_scene_file, load_mesh_scene_file, load_sionna_spec, load_xml_spec

__all__ = [
    "MOVING_VARIANT",
    "Mover",
    "MoverChange",
    "MovingScene",
    "SceneSpec",
    "available_scenes",
    "sionna_scene_names",
    "build_targets",
    "builtin_moving_names",
    "builtin_names",
    "city_names",
    "scene_file",
    "is_scene_path",
    "load_moving_scene",
    "load_scene_spec",
    "tx_pose_error",
]


def _indoor_dir():
    return resources.files("dtradar_data.scenes.indoor")


def indoor_scenes() -> list[str]:
    return sorted(p.name[:-5] for p in _indoor_dir().iterdir() if p.name.endswith(".toml"))


def available_scenes() -> list[str]:
    """The built-in dataset scene names: indoor rooms, city quadrants and Sionna's bundled scenes
    (``sionna-munich``; a build may also say ``sionna:munich``)."""
    return sorted(indoor_scenes() + [q for c in city_names() for q in quadrant_scenes(c)] + sionna_dataset_scenes())


def scene_file(scene: str) -> Path:
    """Path of a built-in scene's file (a city quadrant's is its city's); :class:`UnknownNameError` (with
    did-you-mean) for unknown names."""
    scene = str(_current(scene))
    if scene in indoor_scenes():
        return Path(str(_indoor_dir() / f"{scene}.toml"))
    city = scene.rpartition("-")[0]
    if scene in available_scenes():
        return city_file(city)
    raise unknown_name("scene", scene, available_scenes() + city_names())


def _current(scene: str | Path) -> str | Path:
    """A built-in scene's current name for an old one (:mod:`dtradar_data.core.renamed`); a path as it is."""
    return scene if is_scene_path(scene) else current_scene(str(scene))


def is_scene_path(scene: str | Path) -> bool:
    """Whether ``scene`` names a file rather than a built-in scene (it has a suffix or a directory part)."""
    text = str(scene)
    if isinstance(scene, Path) or text.endswith((".toml", ".xml")):  # sionna-room.toml is a file, not a Sionna scene
        return True
    return not is_sionna_name(text) and ("/" in text or "\\" in text)


def load_scene_spec(
    scene: str | Path,
    variant: str,
    *,
    footprints: str | None = None,
    cell_m: float | None = None,
    grid: tuple | None = None,
    tx: tuple | None = None,
) -> SceneSpec:
    """One variant ("blueprint" or "dynamic") of a built-in scene, a city quadrant or the user's scene file.

    ``footprints`` (cities only) replaces the city's footprint source (a GeoJSON or ``.osm`` file, or ``osm``);
    ``cell_m`` (cities and XML scenes) replaces its cell size; ``grid`` (``X0, Y0, CELL_M, NX, NY``) and ``tx``
    (``X, Y, Z``) replace an XML scene's grid and transmitter (required for a bare ``.xml``).
    """
    scene = _current(scene)
    if variant == MOVING_VARIANT:
        raise InvalidSettingError(
            f"{scene}/{MOVING_VARIANT} is a moving twin, a series of scenes rather than one",
            hint=f"load it with load_moving_scene({str(scene)!r}): a MovingScene whose spec_at(k) is snapshot k",
        )
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, (*VARIANTS, MOVING_VARIANT))
    check_scene_options(footprints=footprints, cell_m=cell_m, grid=grid, tx=tx)  # before any file is read
    mesh_options = {"grid": grid, "tx": tx, "cell_m": cell_m}
    if is_scene_path(scene):
        path = Path(scene).expanduser()
        if not path.is_file():
            raise SceneFileError(
                f"{path}: no such scene file",
                hint="check the path, or use a built-in scene: " + ", ".join(available_scenes()),
            )
        _no_footprints(footprints, str(path))
        if path.suffix.lower() == ".xml":
            return load_xml_spec(path, variant, **mesh_options)
        if is_mesh_scene_file(path):
            return load_mesh_scene_file(path, variant, **mesh_options)
        _indoor_only(footprints, cell_m, str(path), grid, tx)
        spec = load_room_file(path, variant)
        check_user_scene_name(spec.scene, path)
        return spec
    scene = str(scene)
    if is_sionna_name(scene):
        _no_footprints(footprints, scene)
        return load_sionna_spec(scene, variant, **mesh_options)
    _indoor_only(None, None, scene, grid, tx, what="an indoor or city scene")
    if scene in indoor_scenes():
        _indoor_only(footprints, cell_m, scene)
        return load_room_file(scene_file(scene), variant)
    if scene in available_scenes():
        return load_city_spec(scene, variant, footprints=footprints, cell_m=cell_m)
    raise unknown_name("scene", scene, available_scenes() + city_names())


def load_moving_scene(scene: str | Path, *, footprints: str | None = None, cell_m: float | None = None) -> MovingScene:
    """The moving twin of a built-in room (``"cubicle"``), a city quadrant (``"dallas-q3"``) or the user's room file:
    its ``[moving]`` movers over its blueprint (or dynamic twin), every ``dt_s`` seconds for ``snapshots`` steps.

    ``footprints`` and ``cell_m`` apply to city quadrants as in :func:`load_scene_spec`. Scenes built on an XML file
    have no moving twin. :meth:`MovingScene.spec_at` gives each snapshot as a scene; ``build --variant moving``
    traces them all (:mod:`dtradar_data.pipeline.moving`).
    """
    scene = _current(scene)
    check_scene_options(footprints=footprints, cell_m=cell_m)
    if is_scene_path(scene):
        path = Path(scene).expanduser()
        if not path.is_file():
            raise SceneFileError(
                f"{path}: no such scene file",
                hint="check the path, or use a built-in scene: " + ", ".join(available_scenes()),
            )
        if path.suffix.lower() == ".xml" or is_mesh_scene_file(path):
            raise _no_moving_twin(str(path), "a scene built on an XML file")
        _indoor_only(footprints, cell_m, str(path))
        moving = load_moving_room_file(path)
        check_user_scene_name(moving.scene, path)
        return moving
    scene = str(scene)
    if is_sionna_name(scene):
        raise _no_moving_twin(scene, "one of Sionna's bundled scenes")
    if scene in indoor_scenes():
        _indoor_only(footprints, cell_m, scene)
        return load_moving_room_file(scene_file(scene))
    if scene in available_scenes():
        return load_city_moving(scene, footprints=footprints, cell_m=cell_m)
    raise unknown_name("scene", scene, available_scenes() + city_names())


def _no_moving_twin(scene: str, what: str) -> SceneFileError:
    return SceneFileError(
        f"{scene} is {what}: it has no moving twin",
        hint="movers are declared in the [moving] section of a room or city scene file (.toml); "
        "see docs/reference/scene-files.md",
    )


def _indoor_only(footprints, cell_m, scene: str, grid=None, tx=None, what: str = "an indoor scene") -> None:
    if footprints is not None or cell_m is not None:
        raise SceneFileError(
            f"{scene} is an indoor scene: --osm and --cell-m apply to city scenes only",
            hint="edit [grid] in the scene file instead, or drop the option",
        )
    if grid is not None or tx is not None:
        raise SceneFileError(
            f"{scene} is {what}: --grid and --tx apply to XML scenes (sionna:munich, a .xml) only",
            hint="edit [grid] / [tx] in the scene file instead, or drop the option",
        )


def _no_footprints(footprints, scene: str) -> None:
    if footprints is not None:
        raise SceneFileError(f"{scene} is an XML scene: --osm applies to city scenes only", hint="drop --osm")


def builtin_names() -> list[str]:
    """Every built-in ``scene/variant`` dataset name: both twins of each room, each city quadrant's blueprint and
    the dynamic twin of its dynamic quadrant, the blueprint of each of Sionna's bundled scenes."""
    names = [f"{s}/{v}" for s in indoor_scenes() for v in VARIANTS]
    names += [f"{s}/{v}" for c in city_names() for s, v in build_targets(c)]
    names += [f"{s}/blueprint" for s in sionna_dataset_scenes()]
    return sorted(names)


def builtin_moving_names() -> list[str]:
    """Every built-in moving twin (``scene/moving``): each room whose file has a ``[moving]`` section, and the
    quadrant a city's ``[moving]`` names (``build --variant moving`` makes them, ``--variant all`` never does)."""
    names = [f"{s}/{MOVING_VARIANT}" for s in indoor_scenes() if declares_moving(scene_file(s))]
    for city in city_names():
        section = read_city_file(city_file(city)).moving
        if isinstance(section, dict) and section.get("quadrant"):
            names.append(f"{city}-{section['quadrant']}/{MOVING_VARIANT}")
    return sorted(names)


def build_targets(scene: str | Path, variant: str = "all") -> list[tuple[str | Path, str]]:
    """``(scene, variant)`` pairs a build of ``scene`` makes: a city expands to its quadrants (blueprints, plus the
    dynamic twin of its dynamic quadrant); ``variant`` is ``"all"``, ``"blueprint"``, ``"dynamic"`` or ``"moving"``
    (the moving twin only, never part of ``"all"``: a city's is that of the quadrant its ``[moving]`` names)."""
    scene = _current(scene)
    if variant == MOVING_VARIANT:
        return _moving_targets(scene)
    if variant != "all" and variant not in VARIANTS:
        raise unknown_name("variant", variant, ("all", *VARIANTS))
    wanted = VARIANTS if variant == "all" else (variant,)
    text = str(scene)
    if not is_scene_path(scene) and is_sionna_name(text) or is_scene_path(scene) and _is_xml_scene(Path(scene)):
        return [(scene, "blueprint")] if "blueprint" in wanted else [(scene, "dynamic")]  # no dynamic twin: says so
    if not is_scene_path(scene) and text in city_names():
        doc = read_city_file(city_file(text))
        pairs = [(f"{text}-{q}", "blueprint") for q in sorted(doc.quadrants)]
        if doc.dynamic is not None:
            pairs.append((f"{text}-{doc.dynamic.quadrant}", "dynamic"))
        return [(s, v) for s, v in pairs if v in wanted]
    if not is_scene_path(scene) and text not in indoor_scenes():
        parts = text.rpartition("-")
        if text in available_scenes():  # one quadrant: its blueprint, and its dynamic twin when it has one
            doc = read_city_file(city_file(parts[0]))
            has_dynamic = doc.dynamic is not None and doc.dynamic.quadrant == parts[2]
            return [(text, v) for v in wanted if v == "blueprint" or has_dynamic or variant == "dynamic"]
        raise unknown_name("scene", text, available_scenes() + city_names())
    return [(scene, v) for v in wanted]


def _moving_targets(scene: str | Path) -> list[tuple[str | Path, str]]:
    """The moving twin a build of ``scene`` makes; a scene that cannot have one is refused with the reason."""
    text = str(scene)
    if is_scene_path(scene):
        if _is_xml_scene(Path(scene)):
            raise _no_moving_twin(text, "a scene built on an XML file")
        return [(scene, MOVING_VARIANT)]
    if is_sionna_name(text):
        raise _no_moving_twin(text, "one of Sionna's bundled scenes")
    if text in city_names():
        section = read_city_file(city_file(text)).moving
        if not isinstance(section, dict) or not section.get("quadrant"):
            raise SceneFileError(
                f"{text} has no moving twin: {text}.toml declares no [moving] section",
                hint=f"add a [moving] section with quadrant = ... and [[moving.mover]] tables to {text}.toml",
            )
        return [(f"{text}-{section['quadrant']}", MOVING_VARIANT)]
    if text in indoor_scenes() or text in available_scenes():
        return [(scene, MOVING_VARIANT)]
    raise unknown_name("scene", text, available_scenes() + city_names())


def _is_xml_scene(path: Path) -> bool:
    path = path.expanduser()
    return path.suffix.lower() == ".xml" or (path.is_file() and is_mesh_scene_file(path))
