"""The pydantic pieces every scene-file reader shares: the base model of a file's sections and the checked field types.

:class:`SceneFileModel` is frozen and forbids unknown keys, so a misspelt key is an error, never silently ignored. The
field types check a value *before* pydantic converts it (``BeforeValidator``) and fail with a problem and a hint
(:func:`fail`: a ``PydanticCustomError`` of type ``"dtradar"``); each reader turns the first error into a
:class:`~dtradar_data.core.errors.SceneFileError` that names the file, the section or object, and the field.
Used by the room file's models (:mod:`dtradar_data.scenes.indoor.document`), the city file's models
(:mod:`dtradar_data.scenes.city.document`) and the XML scene reader (:mod:`dtradar_data.scenes.xml_scene`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict
from pydantic_core import PydanticCustomError

from dtradar_data.core.errors import did_you_mean
from dtradar_data.core.ids import TX_POSE_SUFFIX
from dtradar_data.scenes.materials import ITU_MATERIALS

__all__ = [
    "NAME_CHARS",
    "SceneFileModel",
    "fail",
    "choice",
    "name_check",
    "Num",
    "Pos",
    "PosInt",
    "Text",
    "Material",
    "SceneName",
    "ObjName",
    "Vec3",
]

NAME_CHARS = "lower-case letters, digits, '-' and '_'"


class SceneFileModel(BaseModel):
    """A section of a scene file: unknown keys are errors, values are frozen."""

    model_config = ConfigDict(extra="forbid", frozen=True)


def fail(problem: str, hint: str) -> PydanticCustomError:
    return PydanticCustomError("dtradar", "{problem}", {"problem": problem, "hint": hint})


def _finite(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise fail(f"must be a finite number, got {value!r}", "write a number, e.g. `1.0`")
    return float(value)


def _positive(value: Any) -> float:
    value = _finite(value)
    if value <= 0:
        raise fail(f"must be > 0, got {value!r}", "give a positive size in metres")
    return value


def _positive_int(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise fail(f"must be a positive integer, got {value!r}", "write e.g. `8`")
    return value


def _text(value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise fail(f"must be a non-empty string, got {value!r}", 'write `"..."`')
    return value.strip()


def choice(choices: tuple[str, ...], what: str) -> Callable[[Any], str]:
    """A validator: one of ``choices`` (``what`` names them in the error, with a did-you-mean)."""

    def check(value: Any) -> str:
        value = _text(value)
        if value not in choices:
            close = did_you_mean(value, choices)
            raise fail(
                f"{value!r} is not {what}" + (f"; {close}" if close else ""), "use one of: " + ", ".join(choices)
            )
        return value

    return check


def name_check(kind_of_name: str, allow_dash: bool) -> Callable[[Any], str]:
    """A validator: a name of lower-case letters, digits and ``_`` (and ``-`` with ``allow_dash``)."""
    chars = NAME_CHARS if allow_dash else "lower-case letters, digits and '_'"

    def check(value: Any) -> str:
        value = _text(value)
        ok = (
            value[0].isalnum()
            and all(c.islower() or c.isdigit() or c == "_" or (allow_dash and c == "-") for c in value)
            and value.isascii()
        )
        if not ok or (not allow_dash and not value[0].isalpha()):
            raise fail(f"{value!r} is not a valid {kind_of_name}", f"use {chars} (e.g. 'chair_01')")
        return value

    return check


def _vec3(value: Any) -> tuple[float, float, float]:
    if not (isinstance(value, list) and len(value) == 3):
        raise fail(f"must be a list of three numbers [x, y, z], got {value!r}", "write e.g. `[1.0, 2.0, 2.9]`")
    return tuple(_finite(v) for v in value)  # type: ignore[return-value]


Num = Annotated[float, BeforeValidator(_finite)]
Pos = Annotated[float, BeforeValidator(_positive)]
PosInt = Annotated[int, BeforeValidator(_positive_int)]
Text = Annotated[str, BeforeValidator(_text)]
Material = Annotated[str, BeforeValidator(choice(ITU_MATERIALS, "an ITU material"))]


def _scene_name(value: Any) -> str:
    value = name_check("scene name", allow_dash=True)(value)
    if value.endswith(TX_POSE_SUFFIX):  # reserved: <scene>-txpose is the antenna-pose-error twin of <scene>
        raise fail(
            f"{value!r} ends in {TX_POSE_SUFFIX!r}, which names antenna-pose-error twins",
            "pick another name; build a pose twin with --tx-pose-error OFFSET_M ANGLE_DEG",
        )
    return value


SceneName = Annotated[str, BeforeValidator(_scene_name)]
ObjName = Annotated[str, BeforeValidator(name_check("name", allow_dash=False))]
Vec3 = Annotated[tuple[float, float, float], BeforeValidator(_vec3)]
