"""Read an indoor scene file (TOML) into a :class:`~dtradar_data.scenes.model.SceneSpec`.

A room scene is a rectangular room (walls, floor, optional ceiling) plus obstacles, each a box as the paper describes
them, and a dataset is only as trustworthy as the scene it was traced in: this module turns a document whose shape
:mod:`dtradar_data.scenes.indoor.document` has checked into the scene, and checks what a schema cannot see (objects
inside the room, the transmitter and grid inside it, unique names, changes that name existing objects), each mistake
a :class:`~dtradar_data.core.errors.SceneFileError` naming the file, the object and the field, and how to fix it. One
file per scene holds the *blueprint* objects and a ``[dynamic]`` section that lists the *changes* (objects added,
moved / re-oriented by name, removed): the dynamic twin is built here as blueprint + changes, so the two variants can
never drift apart silently. A ``[moving]`` section declares people walking through the room: the *moving* twin
(:func:`load_moving_room_file`, a :class:`~dtradar_data.scenes.moving_scene.MovingScene`), read only when asked
for, so the other two never depend on it. The room frame: the interior floor spans ``[0, width_m] x [0, length_m]``
at ``z = 0``; walls stand outside it.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import tomllib
from pydantic import ValidationError

from dtradar_data.core.errors import InvalidSettingError, SceneFileError, did_you_mean
from dtradar_data.core.grid import Grid
from dtradar_data.scenes.indoor.document import (
    FORMAT,
    OBJECT_KEYS,
    DocumentErrors,
    DynamicModel,
    GridModel,
    ObjectModel,
    RoomDocument,
    RoomModel,
    TxModel,
)
from dtradar_data.scenes.model import Box, Room, SceneSpec, TxSpec
from dtradar_data.scenes.moving_scene import MOVING_VARIANT, MovingScene
from dtradar_data.scenes.moving_section import moving_scene_from_section
from dtradar_data.scenes.transmitters import (
    check_one_array,
    check_transmitter_clear,
    check_transmitter_tables,
    tx_label,
    tx_tables,
)

_EPS = 1e-6  # metres: tolerance of the "inside the room" checks (TOML decimals are not exact in binary)
_SIZE_KEYS = ("material", "width_m", "length_m", "height_m")


# ------------------------------------------------------------------------------------------- entry points
def load_room_file(path: str | Path, variant: str) -> SceneSpec:
    """Read and validate a room scene TOML file; :class:`SceneFileError` names the file and field of any problem."""
    return parse_room(_read_toml(path), variant, origin=str(path))


def load_moving_room_file(path: str | Path) -> MovingScene:
    """The moving twin of a room scene TOML file (its ``[moving]`` section over its blueprint or dynamic twin)."""
    return parse_moving_room(_read_toml(path), origin=str(path))


def declares_moving(path: str | Path) -> bool:
    """Whether a room scene file has a ``[moving]`` section, i.e. a moving twin (checked only when it is read)."""
    return isinstance(_read_toml(path).get("moving"), dict)


def parse_room(data: dict[str, Any], variant: str, *, origin: str = "<scene>") -> SceneSpec:
    """Build a :class:`SceneSpec` from an already parsed TOML document (tests and generated scenes)."""
    return _Reader(origin, data).spec(variant)


def parse_moving_room(data: dict[str, Any], *, origin: str = "<scene>") -> MovingScene:
    """Build the moving twin from an already parsed TOML document (tests and generated scenes)."""
    return _Reader(origin, data).moving()


def _read_toml(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(
            f"{path}: cannot read scene file ({getattr(e, 'strerror', None) or e})",
            hint="check the path, or use a built-in scene name (`python -m dtradar_data list`)",
        ) from e
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(
            f"{path}: not valid TOML: {e}", hint="fix the syntax at the reported line (https://toml.io)"
        ) from e
    return data


# ------------------------------------------------------------------------------------------- the reader
class _Reader(DocumentErrors):
    """The :class:`SceneSpec` of one document, with the checks pydantic cannot make."""

    # -- the document
    def document(self) -> RoomDocument:
        fmt = self.data.get("format")
        if "format" in self.data and fmt != FORMAT:
            raise self.fail("format", f"unsupported format {fmt!r}", f"this dtradar reads format = {FORMAT}")
        check_transmitter_tables(self.data, self.origin)  # before pydantic, whose errors would not name them
        try:
            return RoomDocument.model_validate(self.data)
        except ValidationError as exc:
            self.raise_first(exc)
            raise  # pragma: no cover (raise_first always raises)

    def moving(self) -> MovingScene:
        """The moving twin: the ``[moving]`` section over the variant it names as its base."""
        doc = self.document()
        if doc.moving is None:
            raise self.fail(
                "top level",
                "missing section [moving]: this scene has no moving twin",
                "add a [moving] table (description) with [[moving.mover]] tables: see cubicle.toml",
            )
        return moving_scene_from_section(
            doc.moving,
            self.spec,
            origin=self.origin,
            title=doc.scene.title + " (moving twin)",
            description=doc.scene.description,
        )

    def spec(self, variant: str) -> SceneSpec:
        if variant == MOVING_VARIANT:
            raise self.fail(
                "variant",
                "the moving twin is a series of scenes, not one",
                "read it with load_moving_room_file / parse_moving_room (a MovingScene: spec_at(k) is snapshot k)",
            )
        doc = self.document()
        room, structure = self.room(doc.room)
        grid = self.grid(doc.grid, room)
        tables = tx_tables(doc.tx)
        tx, *more_tx = (self.tx(t, room, "[tx]" if len(tables) == 1 else tx_label(k, t)) for k, t in enumerate(tables))
        check_one_array((tx, *more_tx), self.origin)
        for key in ("rx_height_m", "robot_height_m"):
            h = getattr(doc.robot, key)
            if h >= room.height_m:
                raise self.fail(
                    "[robot]",
                    f"{key} = {h} is not below the ceiling ({room.height_m} m)",
                    f"choose {key} between 0 and room.height_m",
                )
        kinds = {k: v.model_dump(exclude_none=True) for k, v in doc.kinds.items()}
        for k in kinds:
            if k in ("floor", "ceiling"):
                raise self.fail(f"[kinds.{k}]", f"invalid kind name {k!r}", "floor and ceiling come from [room]")
        objects = [self.obj(o, ("objects", i), kinds) for i, o in enumerate(doc.objects)]
        description = doc.scene.description
        if variant == "dynamic":
            if doc.dynamic is None:
                raise self.fail(
                    "top level",
                    "missing section [dynamic]",
                    "add a [dynamic] table listing the changes of the dynamic twin",
                )
            objects = self.dynamic(doc.dynamic, objects, kinds)
            description += "\n\nDynamic twin (blueprint + changes): " + doc.dynamic.description
        boxes = structure + objects
        seen: set[str] = set()
        for b in boxes:
            if b.name in seen:
                raise self.fail(
                    f"object {b.name!r}",
                    "duplicate name",
                    "give every object a unique name (walls/floor/ceiling names are reserved)",
                )
            seen.add(b.name)
        for b in objects:
            self.check_inside(b, room)
        meta = doc.scene
        spec = SceneSpec(
            scene=meta.name,
            variant=variant,
            title=meta.title + (" (dynamic twin)" if variant == "dynamic" else " (blueprint)"),
            description=description,
            source=meta.source,
            licence=meta.licence,
            attribution=meta.attribution,
            grid=grid,
            tx=tx,
            more_tx=tuple(more_tx),
            rx_height_m=doc.robot.rx_height_m,
            robot_height_m=doc.robot.robot_height_m,
            objects=tuple(boxes),
            room=room,
        )
        check_transmitter_clear(spec, self.origin)
        return spec

    def room(self, r: RoomModel) -> tuple[Room, list[Box]]:
        W, L, H, wt, ft = r.width_m, r.length_m, r.height_m, r.wall_thickness_m, r.floor_thickness_m
        # Floor and ceiling slabs cover the walls' outer footprint, so the room is closed at the corners.
        ox, oy = W + 2 * wt, L + 2 * wt
        boxes = [Box("floor", "floor", r.floor_material, W / 2, L / 2, ox, oy, ft, z_m=-ft)]
        if (r.ceiling_material is None) != (r.ceiling_thickness_m is None):
            raise self.fail(
                "[room]",
                "ceiling_material and ceiling_thickness_m go together",
                "give both (closed room) or neither (open-top room)",
            )
        if r.ceiling_material is not None:
            boxes.append(
                Box("ceiling", "ceiling", r.ceiling_material, W / 2, L / 2, ox, oy, r.ceiling_thickness_m, z_m=H)
            )
        boxes += [
            Box("wall_south", "wall", r.wall_material, W / 2, -wt / 2, ox, wt, H),
            Box("wall_north", "wall", r.wall_material, W / 2, L + wt / 2, ox, wt, H),
            Box("wall_west", "wall", r.wall_material, -wt / 2, L / 2, wt, L, H),
            Box("wall_east", "wall", r.wall_material, W + wt / 2, L / 2, wt, L, H),
        ]
        return Room(W, L, H), boxes

    def grid(self, g: GridModel, room: Room) -> Grid:
        cell = g.cell_m
        try:
            grid = Grid(
                x0_m=cell / 2 if g.x0_m is None else g.x0_m,
                y0_m=cell / 2 if g.y0_m is None else g.y0_m,
                cell_m=cell,
                nx=g.nx,
                ny=g.ny,
            )
        except InvalidSettingError as e:  # too many cells: the file's mistake, named with its section
            raise self.fail(
                "[grid]",
                e.message.removeprefix("invalid receiver grid: "),
                "use larger cells (cell_m) or fewer (nx, ny)",
            ) from e
        xmin, ymin, xmax, ymax = grid.bounds()
        if xmin < -_EPS or ymin < -_EPS or xmax > room.width_m + _EPS or ymax > room.length_m + _EPS:
            raise self.fail(
                "[grid]",
                f"grid [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}] m is not inside the room "
                f"[0, {room.width_m:g}] x [0, {room.length_m:g}] m",
                "shrink nx/ny or cell_m, or move x0_m/y0_m (cell centres of the first cell)",
            )
        return grid

    def tx(self, t: TxModel, room: Room, where: str = "[tx]") -> TxSpec:
        pos = t.position_m
        if not (0 < pos[0] < room.width_m and 0 < pos[1] < room.length_m and 0 < pos[2] < room.height_m):
            raise self.fail(
                where,
                f"position_m {list(pos)} is outside the room "
                f"(0..{room.width_m:g}, 0..{room.length_m:g}, 0..{room.height_m:g} m)",
                "put the transmitter inside the room, e.g. just below the ceiling",
            )
        if t.look_at_m is not None and np.allclose(t.look_at_m, pos):
            raise self.fail(where, "look_at_m equals position_m", "point the array at another point, e.g. the floor")
        return TxSpec(
            position_m=pos,
            look_at_m=t.look_at_m,
            num_rows=t.num_rows,
            num_cols=t.num_cols,
            pattern=t.pattern,
            polarization=t.polarization,
            power_dbm=t.power_dbm,
            name=t.name,
        )

    def obj(self, raw: Any, loc: tuple, kinds: dict[str, dict[str, Any]]) -> Box:
        where = self.where(loc)
        if not isinstance(raw, dict):
            raise self.fail(where, "must be a table", "write it as an [[objects]] block")
        kind = raw.get("kind")
        if isinstance(kind, str) and kind in ("floor", "ceiling"):
            raise self.fail(where, f"invalid kind {kind!r}", "floor and ceiling come from [room]")
        merged = {**kinds.get(kind, {}), **raw} if isinstance(kind, str) else dict(raw)
        for key in _SIZE_KEYS:
            if key not in merged and set(raw) <= set(OBJECT_KEYS) and {"name", "kind", "x_m", "y_m"} <= set(raw):
                known = did_you_mean(str(kind), kinds)
                raise self.fail(
                    where,
                    f"missing field {key!r} (and no [kinds.{kind}] default)"
                    + (f"; kind {known}" if known and kind not in kinds else ""),
                    f"add `{key} = ...` to the object or to a [kinds.{kind}] table",
                )
        try:
            o = ObjectModel.model_validate(merged)
        except ValidationError as exc:
            self.raise_first(exc, loc)
        return Box(
            name=o.name,
            kind=o.kind,
            material=o.material,
            x_m=o.x_m,
            y_m=o.y_m,
            width_m=o.width_m,
            length_m=o.length_m,
            height_m=o.height_m,
            z_m=o.z_m,
            yaw_deg=o.yaw_deg,
        )

    def dynamic(self, d: DynamicModel, objects: list[Box], kinds: dict[str, dict[str, Any]]) -> list[Box]:
        """Apply the [dynamic] changes in a fixed order: remove, move (in place), add (appended)."""
        by_name = {b.name: i for i, b in enumerate(objects)}
        out: list[Box | None] = list(objects)
        for n in d.remove:
            if n not in by_name or out[by_name[n]] is None:
                raise self._unknown_object("[dynamic] remove", n, by_name)
            out[by_name[n]] = None
        for i, m in enumerate(d.move):
            where = f"dynamic.move[{i}]"
            if m.name not in by_name or out[by_name[m.name]] is None:
                raise self._unknown_object(where, m.name, by_name)
            changes = m.model_dump(exclude_none=True, exclude={"name"})
            if not changes:
                raise self.fail(
                    where, f"move of {m.name!r} changes nothing", "give at least one of x_m, y_m, z_m, yaw_deg"
                )
            out[by_name[m.name]] = replace(out[by_name[m.name]], **changes)
        added = [self.obj(a, ("add", i), kinds) for i, a in enumerate(d.add)]
        return [b for b in out if b is not None] + added

    def _unknown_object(self, where: str, name: str, by_name: dict) -> SceneFileError:
        close = did_you_mean(name, by_name)
        return self.fail(
            where,
            f"no blueprint object named {name!r}" + (f"; {close}" if close else ""),
            "name an object from [[objects]]",
        )

    def check_inside(self, b: Box, room: Room) -> None:
        c = b.corners()
        if (
            c[:, 0].min() < -_EPS
            or c[:, 1].min() < -_EPS
            or c[:, 0].max() > room.width_m + _EPS
            or c[:, 1].max() > room.length_m + _EPS
        ):
            raise self.fail(
                f"object {b.name!r}",
                f"footprint x {c[:, 0].min():.3f}..{c[:, 0].max():.3f}, y {c[:, 1].min():.3f}.."
                f"{c[:, 1].max():.3f} m is outside the room "
                f"[0, {room.width_m:g}] x [0, {room.length_m:g}] m",
                "move it (x_m, y_m), shrink it, or change yaw_deg so it fits inside the walls",
            )
        if b.z_m < -_EPS or b.top_m > room.height_m + _EPS:
            raise self.fail(
                f"object {b.name!r}",
                f"spans z {b.z_m:g}..{b.top_m:g} m, outside the room's 0..{room.height_m:g} m",
                "fix z_m or height_m",
            )
