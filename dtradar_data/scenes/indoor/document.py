"""The shape of an indoor scene file (TOML), as pydantic models, and pydantic's complaints in the file's own words.

A scene file is written by hand, so a mistake in it has to be reported where the author will look: the section, the
object by index and name, the key, with a fix; pydantic's raw error locations (``('objects', 1, 'width_m')``, union
branches) say none of that. Keeping the models and the translation of their errors together, apart from the reader
(:mod:`dtradar_data.scenes.indoor.reader`) that builds the scene from a valid document, keeps the file format in one
place. The layout (``cubicle.toml`` beside this module is a commented example)::

    format = 1
    [scene]    name, title, description, source, licence, attribution
    [room]     width_m (x), length_m (y), height_m, wall_thickness_m, wall_material, floor_material,
               floor_thickness_m, [ceiling_material, ceiling_thickness_m]
    [grid]     cell_m, nx, ny, [x0_m, y0_m]          (default: first cell centre at cell_m/2 from the corner)
    [tx]       position_m, [look_at_m, num_rows, num_cols, pattern, polarization, power_dbm]
    [robot]    rx_height_m, robot_height_m
    [kinds.<kind>]   defaults for objects of that kind: material, width_m, length_m, height_m, [z_m, yaw_deg]
    [[objects]]      name, kind, x_m, y_m, [material, width_m, length_m, height_m, z_m, yaw_deg]
    [dynamic]        description, [[dynamic.add]] (like objects), [[dynamic.move]] (name + fields to change),
                     remove = [names]
    [moving]         description, [base, dt_s, horizon_s], [[moving.mover]] (name, kind, speed_mps, waypoints,
                     [mode, start_offset_s, material, width_m, length_m, height_m, mesh]): read only for the
                     moving twin (:mod:`dtradar_data.scenes.moving_section`), so it never changes the other two
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator, ValidationError

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.fields import (
    Material,
    Num,
    ObjName,
    Pos,
    PosInt,
    SceneFileModel,
    SceneName,
    Text,
    Vec3,
    choice,
    name_check,
)
from dtradar_data.scenes.model import PATTERNS, POLARIZATIONS

FORMAT = 1


# ------------------------------------------------------------------------------------------- document models
class SceneMeta(SceneFileModel):
    name: SceneName
    title: Text
    description: Text
    source: Text
    licence: Text
    attribution: Text


class RoomModel(SceneFileModel):
    width_m: Pos
    length_m: Pos
    height_m: Pos
    wall_thickness_m: Pos
    wall_material: Material
    floor_material: Material
    floor_thickness_m: Pos
    ceiling_material: Material | None = None
    ceiling_thickness_m: Pos | None = None


class GridModel(SceneFileModel):
    cell_m: Pos
    nx: PosInt
    ny: PosInt
    x0_m: Num | None = None
    y0_m: Num | None = None


class TxModel(SceneFileModel):
    name: str | None = None
    position_m: Vec3
    look_at_m: Vec3 | None = None
    num_rows: PosInt = 8
    num_cols: PosInt = 2
    pattern: Annotated[str, BeforeValidator(choice(PATTERNS, "an antenna pattern"))] = "tr38901"
    polarization: Annotated[str, BeforeValidator(choice(POLARIZATIONS, "a polarization"))] = "VH"
    power_dbm: Num = 0.0


class RobotModel(SceneFileModel):
    rx_height_m: Pos
    robot_height_m: Pos


class KindDefaults(SceneFileModel):
    material: Material | None = None
    width_m: Pos | None = None
    length_m: Pos | None = None
    height_m: Pos | None = None
    z_m: Num | None = None
    yaw_deg: Num | None = None


class ObjectModel(SceneFileModel):
    name: ObjName
    kind: ObjName
    x_m: Num
    y_m: Num
    material: Material
    width_m: Pos
    length_m: Pos
    height_m: Pos
    z_m: Num = 0.0
    yaw_deg: Num = 0.0


class MoveModel(SceneFileModel):
    name: Text
    x_m: Num | None = None
    y_m: Num | None = None
    z_m: Num | None = None
    yaw_deg: Num | None = None


class DynamicModel(SceneFileModel):
    description: Text
    add: list[dict[str, Any]] = []
    move: list[MoveModel] = []
    remove: list[Text] = []


class RoomDocument(SceneFileModel):
    format: int
    scene: SceneMeta
    room: RoomModel
    grid: GridModel
    tx: TxModel | list[TxModel]
    """One ``[tx]`` table, or one ``[[tx]]`` table per transmitter (the first is transmitter 0)."""
    robot: RobotModel
    kinds: dict[Annotated[str, BeforeValidator(name_check("kind name", allow_dash=False))], KindDefaults] = {}
    objects: list[dict[str, Any]]
    dynamic: DynamicModel | None = None
    moving: dict[str, Any] | None = None
    """Checked only when the moving twin is read
    (:func:`dtradar_data.scenes.moving_section.moving_scene_from_section`)."""


OBJECT_KEYS = tuple(ObjectModel.model_fields)
_SECTION_HINTS = {
    "scene": "name, title, description, source, licence, attribution",
    "room": "width_m, ...",
    "grid": "cell_m, nx, ny",
    "tx": "position_m",
    "robot": "rx_height_m, robot_height_m",
    "objects": "[[objects]] blocks",
}


# ------------------------------------------------------------------------------------------- errors
class DocumentErrors:
    """The :class:`SceneFileError` of a problem in one scene document, worded the way the file is written."""

    def __init__(self, origin: str, data: dict[str, Any]):
        self.origin = origin
        self.data = data

    def fail(self, where: str, problem: str, hint: str) -> SceneFileError:
        return SceneFileError(f"{self.origin}: {where}: {problem}", hint=hint)

    # pydantic's error locations, spoken the way the file is written: "[room]", "objects[1] 'table_01'", ...
    def where(self, loc: tuple) -> str:
        if not loc:
            return "top level"
        head = loc[0]
        if head in ("objects", "add") and len(loc) > 1 and isinstance(loc[1], int):
            items = self.data.get("objects") if head == "objects" else (self.data.get("dynamic") or {}).get("add")
            prefix = "objects" if head == "objects" else "dynamic.add"
            name = items[loc[1]].get("name") if isinstance(items, list) and isinstance(items[loc[1]], dict) else None
            return f"{prefix}[{loc[1]}]" + (f" {name!r}" if isinstance(name, str) else "")
        if head == "dynamic" and len(loc) > 2 and isinstance(loc[2], int):
            return f"dynamic.{loc[1]}[{loc[2]}]"
        if head == "kinds" and len(loc) > 1:
            return f"[kinds.{loc[1]}]"
        return f"[{head}]" if len(loc) > 1 else "top level"

    def raise_first(self, exc: ValidationError, base_loc: tuple = ()) -> None:
        errors = exc.errors()
        # A misspelt key also makes the right one "missing": report the misspelling, it explains both.
        errors.sort(key=lambda e: e["type"] != "extra_forbidden")
        e = errors[0]
        loc = base_loc + tuple(e["loc"])
        # a union (e.g. `Material | None`) reports its branch in the location: keep only the field names
        loc = tuple(p for p in loc if not (isinstance(p, str) and ("[" in p or p in ("function-before", "none"))))
        where, field = self.where(loc), next((p for p in reversed(loc) if isinstance(p, str)), None)
        more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
        if e["type"] == "extra_forbidden":
            parent = self.allowed_keys(loc[:-1])
            close = did_you_mean(str(field), parent)
            raise self.fail(
                where,
                f"unknown key {field!r}" + (f"; {close}" if close else "") + more,
                "allowed keys: " + ", ".join(sorted(parent)),
            )
        if e["type"] == "missing":
            if len(loc) == 1:
                raise self.fail(
                    where,
                    f"missing section [{field}]" + more,
                    f"add a [{field}] table ({_SECTION_HINTS.get(field, 'see cubicle.toml')})",
                )
            raise self.fail(where, f"missing field {field!r}" + more, f"add `{field} = ...` to {where}")
        if e["type"] == "dtradar":
            raise self.fail(where, f"{field} {e['ctx']['problem']}" + more, e["ctx"]["hint"])
        if e["type"] in ("model_type", "dict_type"):
            raise self.fail(where, f"{field or 'this'} must be a table" + more, "write key = value lines under it")
        if e["type"] == "list_type":
            raise self.fail(
                where,
                f"{field} must be an array" + more,
                f"write each entry as a [[{'.'.join(str(p) for p in loc)}]] block or a [list]",
            )
        raise self.fail(where, f"{field}: {e['msg']}" + more, "see cubicle.toml for the expected form")

    def allowed_keys(self, loc: tuple) -> tuple[str, ...]:
        model = {
            (): RoomDocument,
            ("scene",): SceneMeta,
            ("room",): RoomModel,
            ("grid",): GridModel,
            ("tx",): TxModel,
            ("robot",): RobotModel,
            ("dynamic",): DynamicModel,
        }.get(tuple(loc[:1]))
        if loc and loc[0] in ("objects", "add") or (len(loc) > 1 and loc[:2] == ("dynamic", "add")):
            return OBJECT_KEYS
        if len(loc) > 1 and loc[0] == "kinds":
            return tuple(KindDefaults.model_fields)
        if len(loc) > 2 and loc[:2] == ("dynamic", "move"):
            return tuple(MoveModel.model_fields)
        return tuple((model or RoomDocument).model_fields)
