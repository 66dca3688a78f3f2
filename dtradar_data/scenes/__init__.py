"""Scenes: the scene model, its materials, and the catalogue of scenes a user can name.

A scene is named by a built-in name (``cubicle``, ``meeting``: TOML files in :mod:`dtradar_data.scenes.indoor`) or
by the path of the user's own scene file (``make dataset SCENE=path/to/room.toml``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from dtradar_data.core.errors import SceneFileError, unknown_name
from dtradar_data.core.ids import VARIANTS
from dtradar_data.scenes.indoor.reader import load_room_file
from dtradar_data.scenes.model import SceneSpec

__all__ = ["SceneSpec", "available_scenes", "scene_file", "is_scene_path", "load_scene_spec"]


def _indoor_dir():
    return resources.files("dtradar_data.scenes.indoor")


def available_scenes() -> list[str]:
    """The built-in scene names."""
    return sorted(p.name[:-5] for p in _indoor_dir().iterdir() if p.name.endswith(".toml"))


def scene_file(scene: str) -> Path:
    """Path of a built-in scene's file; :class:`UnknownNameError` (with did-you-mean) for unknown names."""
    names = available_scenes()
    if scene not in names:
        raise unknown_name("scene", scene, names)
    return Path(str(_indoor_dir() / f"{scene}.toml"))


def is_scene_path(scene: str | Path) -> bool:
    """Whether ``scene`` names a file rather than a built-in scene (it has a suffix or a directory part)."""
    text = str(scene)
    return isinstance(scene, Path) or text.endswith(".toml") or "/" in text or "\\" in text


def load_scene_spec(scene: str | Path, variant: str) -> SceneSpec:
    """One variant ("blueprint" or "dynamic") of a built-in scene or of the user's scene file."""
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, VARIANTS)
    if is_scene_path(scene):
        path = Path(scene).expanduser()
        if not path.is_file():
            raise SceneFileError(f"{path}: no such scene file",
                                 hint="check the path, or use a built-in scene: " + ", ".join(available_scenes()))
        return load_room_file(path, variant)
    return load_room_file(scene_file(str(scene)), variant)
