"""Scene model: the digital twins of DT-RaDaR Module 1 as frozen, validated data.

A scene is a rectangular room (walls, floor, optional ceiling) plus obstacles. Every obstacle is a box as the paper
describes them, ``(x, y, height, width, length)``, with a yaw about +z, a bottom height ``z`` (laptops sit on tables)
and an ITU material as Sionna names them. Scene descriptions are data: one TOML file per scene in
``dtradar_data/scenes/``, holding the *blueprint* objects and a ``[dynamic]`` section that lists the *changes*
(objects added, moved / re-oriented by name, removed). The dynamic twin is blueprint + changes, so the two variants
can never drift apart silently.

File layout (see ``scenes/cubicle.toml`` for a commented example)::

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

The room frame: interior floor spans ``[0, width_m] x [0, length_m]`` at ``z = 0``; walls stand outside it.
Every mistake raises :class:`~dtradar_data.errors.SceneFileError` naming the file, the object and the field.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InvalidCoordinatesError, SceneFileError, did_you_mean, unknown_name

# Every ITU-R P.2040 material Sionna RT 2.x knows (sionna/rt/radio_materials/itu.py). Not all are defined at
# every frequency: see ITU_VALID_GHZ and material_valid_at().
ITU_VALID_GHZ: dict[str, tuple[float, float]] = {
    "vacuum": (0.001, 100.0), "concrete": (1.0, 100.0), "brick": (1.0, 40.0), "plasterboard": (1.0, 100.0),
    "wood": (0.001, 100.0), "glass": (0.1, 100.0), "clear_acrylic": (110.0, 330.0), "ceiling_board": (1.0, 100.0),
    "chipboard": (1.0, 100.0), "plywood": (1.0, 40.0), "marble": (1.0, 60.0), "floorboard": (50.0, 100.0),
    "vinyl_tile": (1.0, 40.0), "carpet_tile": (1.0, 40.0), "asphalt_concrete": (1.0, 40.0), "metal": (1.0, 100.0),
    "very_dry_ground": (1.0, 10.0), "medium_dry_ground": (1.0, 10.0), "wet_ground": (1.0, 10.0),
}
ITU_MATERIALS: tuple[str, ...] = tuple(ITU_VALID_GHZ)
VARIANTS = ("blueprint", "dynamic")
STRUCTURE_KINDS = ("wall", "floor", "ceiling")  # generated from [room]; walls also obstruct the robot
PATTERNS = ("iso", "dipole", "hw_dipole", "tr38901")
POLARIZATIONS = ("V", "H", "VH", "cross")
FORMAT = 1

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_-]*$")
_KIND_RE = re.compile(r"^[a-z][a-z0-9_]*$")
_EPS = 1e-6  # metres: tolerance of the "inside the room" checks (TOML decimals are not exact in binary)


def material_valid_at(material: str, frequency_hz: float) -> bool:
    """Whether ITU-R P.2040 (and so Sionna) defines ``material`` at ``frequency_hz``."""
    lo, hi = ITU_VALID_GHZ[material]
    return lo <= frequency_hz / 1e9 <= hi


# ---------------------------------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class Box:
    """One obstacle (or wall / floor / ceiling slab): a box of ``width_m`` (local x) x ``length_m`` (local y) x
    ``height_m``, footprint centred at ``(x_m, y_m)``, bottom at ``z_m``, rotated ``yaw_deg`` counter-clockwise."""

    name: str
    kind: str
    material: str
    x_m: float
    y_m: float
    width_m: float
    length_m: float
    height_m: float
    z_m: float = 0.0
    yaw_deg: float = 0.0

    @property
    def top_m(self) -> float:
        return self.z_m + self.height_m

    def corners(self) -> np.ndarray:
        """Footprint corners, float64[4, 2], counter-clockwise."""
        hw, hl = self.width_m / 2, self.length_m / 2
        local = np.array([[-hw, -hl], [hw, -hl], [hw, hl], [-hw, hl]])
        t = math.radians(self.yaw_deg)
        rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
        return local @ rot.T + np.array([self.x_m, self.y_m])


@dataclass(frozen=True)
class Grid:
    """The receiver grid: ``nx`` x ``ny`` square cells of ``cell_m``; ``(x0_m, y0_m)`` is the centre of cell (0, 0)."""

    x0_m: float
    y0_m: float
    cell_m: float
    nx: int
    ny: int

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``: arrays over the grid are indexed ``[iy, ix]`` (row-major, y outer)."""
        return (self.ny, self.nx)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.x0_m + self.cell_m * np.arange(self.nx, dtype=np.float64),
                self.y0_m + self.cell_m * np.arange(self.ny, dtype=np.float64))

    def bounds(self) -> tuple[float, float, float, float]:
        """Outer edges ``(xmin, ymin, xmax, ymax)`` of the grid's cells."""
        h = self.cell_m / 2
        return (self.x0_m - h, self.y0_m - h,
                self.x0_m + (self.nx - 1) * self.cell_m + h, self.y0_m + (self.ny - 1) * self.cell_m + h)

    def index_of(self, x: float, y: float) -> tuple[int, int]:
        """``(ix, iy)`` of the cell holding the point; a point on the grid's far edge belongs to the last cell."""
        fx, fy = (x - self.x0_m) / self.cell_m + 0.5, (y - self.y0_m) / self.cell_m + 0.5
        ix, iy = math.floor(fx), math.floor(fy)
        ix = self.nx - 1 if ix == self.nx and fx - self.nx < 1e-9 else ix
        iy = self.ny - 1 if iy == self.ny and fy - self.ny < 1e-9 else iy
        if not (0 <= ix < self.nx and 0 <= iy < self.ny) or not (math.isfinite(x) and math.isfinite(y)):
            xmin, ymin, xmax, ymax = self.bounds()
            raise InvalidCoordinatesError(
                f"point ({x}, {y}) is outside the grid [{xmin}, {xmax}] x [{ymin}, {ymax}] m",
                hint="use coordinates in the scene frame inside the grid")
        return ix, iy

    def to_dict(self) -> dict[str, Any]:
        return {"x0_m": self.x0_m, "y0_m": self.y0_m, "cell_m": self.cell_m, "nx": self.nx, "ny": self.ny}

    @classmethod
    def from_meta(cls, grid: dict[str, Any]) -> Grid:
        """The grid recorded in a dataset's metadata (``meta["grid"]``, as written by :meth:`to_dict`)."""
        return cls(float(grid["x0_m"]), float(grid["y0_m"]), float(grid["cell_m"]), int(grid["nx"]), int(grid["ny"]))


@dataclass(frozen=True)
class TxSpec:
    """The transmitter: an ``num_rows`` x ``num_cols`` planar array (paper: 8 x 2, tr38901, dual-polarised)."""

    position_m: tuple[float, float, float]
    look_at_m: tuple[float, float, float] | None = None
    num_rows: int = 8
    num_cols: int = 2
    pattern: str = "tr38901"
    polarization: str = "VH"
    power_dbm: float = 0.0


@dataclass(frozen=True)
class Room:
    """Interior dimensions: the floor spans ``[0, width_m] x [0, length_m]``; the ceiling (if any) is at
    ``height_m``."""

    width_m: float
    length_m: float
    height_m: float


@dataclass(frozen=True)
class SceneSpec:
    """Everything that defines one variant of one scene; its :meth:`digest` identifies it in dataset versions."""

    scene: str
    variant: str
    title: str
    description: str
    source: str
    licence: str
    attribution: str
    grid: Grid
    tx: TxSpec
    rx_height_m: float
    robot_height_m: float
    objects: tuple[Box, ...]
    room: Room | None = None

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.variant}"

    def obstacles(self) -> tuple[Box, ...]:
        """Objects that can obstruct the robot: everything except floor and ceiling slabs."""
        return tuple(b for b in self.objects if b.kind not in ("floor", "ceiling"))

    def count_by_kind(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for b in self.objects:
            counts[b.kind] = counts.get(b.kind, 0) + 1
        return counts

    def to_dict(self) -> dict[str, Any]:
        """JSON-able and canonical: tuples become lists, key order is fixed by :meth:`digest`'s ``sort_keys``."""
        d = asdict(self)
        d["objects"] = [asdict(b) for b in self.objects]
        d["tx"]["position_m"] = list(self.tx.position_m)
        d["tx"]["look_at_m"] = None if self.tx.look_at_m is None else list(self.tx.look_at_m)
        return d

    def canonical_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)

    def digest(self) -> str:
        """sha256 hex of the canonical JSON: equal specs, equal digests, whatever file they were read from."""
        return hashlib.sha256(self.canonical_json().encode("ascii")).hexdigest()


# ---------------------------------------------------------------------------------------------------- loading
def _scenes_dir():
    return resources.files("dtradar_data") / "scenes"


def available_scenes() -> list[str]:
    """Scenes that have a TOML file in ``dtradar_data/scenes/``."""
    return sorted(p.name[:-5] for p in _scenes_dir().iterdir() if p.name.endswith(".toml"))


def scene_file(scene: str) -> Path:
    """Path of a built-in scene's TOML file; :class:`UnknownNameError` (with did-you-mean) for unknown names."""
    names = available_scenes()
    if scene not in names:
        raise unknown_name("scene", scene, names)
    return Path(str(_scenes_dir() / f"{scene}.toml"))


def load_scene_spec(scene: str, variant: str) -> SceneSpec:
    """The built-in scene ``scene`` in ``variant`` ("blueprint" or "dynamic")."""
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, VARIANTS)
    return load_scene_file(scene_file(scene), variant)


def load_scene_file(path: str | Path, variant: str) -> SceneSpec:
    """Read and validate a scene TOML file; :class:`SceneFileError` names the file and field of any problem."""
    path = Path(path)
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, VARIANTS)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise SceneFileError(f"{path}: cannot read scene file ({e.strerror})",
                             hint="check the path; built-in scenes: " + ", ".join(available_scenes())) from e
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{path}: not valid TOML: {e}",
                             hint="fix the syntax at the reported line (https://toml.io)") from e
    return parse_scene(data, variant, origin=str(path))


def parse_scene(data: dict[str, Any], variant: str, *, origin: str = "<scene>") -> SceneSpec:
    """Build a :class:`SceneSpec` from an already parsed TOML document (useful for tests and generated scenes)."""
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, VARIANTS)
    return _Parser(origin).parse(data, variant)


# ---------------------------------------------------------------------------------------------------- validation
_BOX_FIELDS = ("material", "width_m", "length_m", "height_m", "z_m", "yaw_deg")
_OBJECT_KEYS = {"name", "kind", "x_m", "y_m", *_BOX_FIELDS}
_MOVE_KEYS = {"name", "x_m", "y_m", "z_m", "yaw_deg"}


@dataclass
class _Parser:
    origin: str
    kinds: dict[str, dict[str, Any]] = field(default_factory=dict)

    # -- error helpers
    def fail(self, where: str, problem: str, hint: str) -> SceneFileError:
        return SceneFileError(f"{self.origin}: {where}: {problem}", hint=hint)

    def table(self, data: dict, key: str, where: str, *, required: bool = True) -> dict:
        if key not in data:
            if required:
                raise self.fail(where, f"missing section [{key}]", f"add a [{key}] table (see scenes/cubicle.toml)")
            return {}
        value = data[key]
        if not isinstance(value, dict):
            raise self.fail(f"{where}{key}", "must be a table", f"write it as [{key}] with key = value lines")
        return value

    def keys(self, table: dict, allowed: set[str], required: set[str], where: str) -> None:
        for key in table:
            if key not in allowed:
                close = did_you_mean(key, allowed)
                raise self.fail(where, f"unknown key {key!r}" + (f"; {close}" if close else ""),
                                "allowed keys: " + ", ".join(sorted(allowed)))
        for key in sorted(required - set(table)):
            raise self.fail(where, f"missing field {key!r}", f"add `{key} = ...` to {where}")

    def number(self, table: dict, key: str, where: str, *, positive: bool = False, default: Any = None) -> float:
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"{key} must be a finite number, got {value!r}", f"write e.g. `{key} = 1.0`")
        if positive and value <= 0:
            raise self.fail(where, f"{key} must be > 0, got {value!r}", f"give {key} a positive size in metres")
        return float(value)

    def integer(self, table: dict, key: str, where: str, *, default: Any = None) -> int:
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise self.fail(where, f"{key} must be a positive integer, got {value!r}", f"write e.g. `{key} = 8`")
        return value

    def string(self, table: dict, key: str, where: str, *, default: Any = None) -> str:
        value = table.get(key, default)
        if not isinstance(value, str) or not value.strip():
            raise self.fail(where, f"{key} must be a non-empty string, got {value!r}", f'write `{key} = "..."`')
        return value

    def choice(self, table: dict, key: str, where: str, choices, *, default: Any = None) -> str:
        value = self.string(table, key, where, default=default)
        if value not in choices:
            close = did_you_mean(value, choices)
            raise self.fail(where, f"{key} {value!r} is not an allowed value" + (f"; {close}" if close else ""),
                            "use one of: " + ", ".join(choices))
        return value

    def material(self, table: dict, key: str, where: str, *, default: Any = None) -> str:
        value = self.string(table, key, where, default=default)
        if value not in ITU_MATERIALS:
            close = did_you_mean(value, ITU_MATERIALS)
            raise self.fail(where, f"{key} {value!r} is not an ITU material" + (f"; {close}" if close else ""),
                            "use one of Sionna's ITU materials: " + ", ".join(ITU_MATERIALS))
        return value

    def vec3(self, table: dict, key: str, where: str) -> tuple[float, float, float]:
        value = table.get(key)
        ok = isinstance(value, list) and len(value) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        if not ok:
            raise self.fail(where, f"{key} must be a list of three numbers [x, y, z], got {value!r}",
                            f"write e.g. `{key} = [1.0, 2.0, 2.9]`")
        return (float(value[0]), float(value[1]), float(value[2]))

    # -- sections
    def parse(self, data: dict, variant: str) -> SceneSpec:
        top = {"format", "scene", "room", "grid", "tx", "robot", "kinds", "objects", "dynamic"}
        self.keys(data, top, top - {"kinds", "dynamic"}, "top level")
        if data["format"] != FORMAT:
            raise self.fail("format", f"unsupported format {data['format']!r}", f"this dtradar reads format = {FORMAT}")
        meta = self.table(data, "scene", "")
        meta_keys = {"name", "title", "description", "source", "licence", "attribution"}
        self.keys(meta, meta_keys, meta_keys, "[scene]")
        name = self.string(meta, "name", "[scene]")
        if not _NAME_RE.match(name):
            raise self.fail("[scene]", f"name {name!r} is not a valid scene name",
                            "use lower-case letters, digits, '-' and '_' (e.g. 'cubicle')")
        room, structure = self.room(self.table(data, "room", ""))
        self.kinds = self.kind_defaults(data.get("kinds", {}))
        grid = self.grid(self.table(data, "grid", ""), room)
        tx = self.tx(self.table(data, "tx", ""), room)
        robot = self.table(data, "robot", "")
        self.keys(robot, {"rx_height_m", "robot_height_m"}, {"rx_height_m", "robot_height_m"}, "[robot]")
        rx_h = self.number(robot, "rx_height_m", "[robot]", positive=True)
        robot_h = self.number(robot, "robot_height_m", "[robot]", positive=True)
        for key, h in (("rx_height_m", rx_h), ("robot_height_m", robot_h)):
            if h >= room.height_m:
                raise self.fail("[robot]", f"{key} = {h} is not below the ceiling ({room.height_m} m)",
                                f"choose {key} between 0 and room.height_m")

        objects_list = data["objects"]
        if not isinstance(objects_list, list):
            raise self.fail("objects", "must be an array of tables", "write each object as an [[objects]] block")
        objects = [self.obj(o, f"objects[{i}]") for i, o in enumerate(objects_list)]
        description = meta["description"].strip()
        if variant == "dynamic":
            objects, changes = self.dynamic(self.table(data, "dynamic", "", required=True), objects)
            description += "\n\nDynamic twin (blueprint + changes): " + changes
        boxes = structure + objects
        self.check_unique(boxes)
        for b in objects:
            self.check_inside(b, room)
        return SceneSpec(scene=name, variant=variant,
                         title=meta["title"].strip() + (" (dynamic twin)" if variant == "dynamic" else " (blueprint)"),
                         description=description, source=meta["source"].strip(), licence=meta["licence"].strip(),
                         attribution=meta["attribution"].strip(), grid=grid, tx=tx, rx_height_m=rx_h,
                         robot_height_m=robot_h, objects=tuple(boxes), room=room)

    def room(self, t: dict) -> tuple[Room, list[Box]]:
        w = "[room]"
        allowed = {"width_m", "length_m", "height_m", "wall_thickness_m", "wall_material", "floor_material",
                   "floor_thickness_m", "ceiling_material", "ceiling_thickness_m"}
        self.keys(t, allowed, allowed - {"ceiling_material", "ceiling_thickness_m"}, w)
        W, L, H = (self.number(t, k, w, positive=True) for k in ("width_m", "length_m", "height_m"))
        wt = self.number(t, "wall_thickness_m", w, positive=True)
        ft = self.number(t, "floor_thickness_m", w, positive=True)
        wall_mat, floor_mat = self.material(t, "wall_material", w), self.material(t, "floor_material", w)
        # Floor and ceiling slabs cover the walls' outer footprint, so the room is closed at the corners.
        ox, oy = W + 2 * wt, L + 2 * wt
        boxes = [Box("floor", "floor", floor_mat, W / 2, L / 2, ox, oy, ft, z_m=-ft)]
        if ("ceiling_material" in t) != ("ceiling_thickness_m" in t):
            raise self.fail(w, "ceiling_material and ceiling_thickness_m go together",
                            "give both (closed room) or neither (open-top room)")
        if "ceiling_material" in t:
            ct = self.number(t, "ceiling_thickness_m", w, positive=True)
            boxes.append(Box("ceiling", "ceiling", self.material(t, "ceiling_material", w), W / 2, L / 2, ox, oy, ct,
                             z_m=H))
        boxes += [Box("wall_south", "wall", wall_mat, W / 2, -wt / 2, ox, wt, H),
                  Box("wall_north", "wall", wall_mat, W / 2, L + wt / 2, ox, wt, H),
                  Box("wall_west", "wall", wall_mat, -wt / 2, L / 2, wt, L, H),
                  Box("wall_east", "wall", wall_mat, W + wt / 2, L / 2, wt, L, H)]
        return Room(W, L, H), boxes

    def kind_defaults(self, kinds: Any) -> dict[str, dict[str, Any]]:
        if not isinstance(kinds, dict):
            raise self.fail("kinds", "must be a table of tables", "write [kinds.chair] with material, sizes")
        out = {}
        for kind, t in kinds.items():
            w = f"[kinds.{kind}]"
            if not isinstance(t, dict):
                raise self.fail(w, "must be a table", "write key = value lines under it")
            if not _KIND_RE.match(kind) or kind in ("floor", "ceiling"):
                raise self.fail(w, f"invalid kind name {kind!r}",
                                "use lower-case letters, digits and '_'; floor/ceiling come from [room]")
            self.keys(t, set(_BOX_FIELDS), set(), w)
            # Check the defaults here, so a bad default is reported against [kinds.x] even if no object uses it.
            if "material" in t:
                self.material(t, "material", w)
            for key in ("width_m", "length_m", "height_m"):
                if key in t:
                    self.number(t, key, w, positive=True)
            for key in ("z_m", "yaw_deg"):
                if key in t:
                    self.number(t, key, w)
            out[kind] = dict(t)
        return out

    def grid(self, t: dict, room: Room) -> Grid:
        w = "[grid]"
        self.keys(t, {"cell_m", "nx", "ny", "x0_m", "y0_m"}, {"cell_m", "nx", "ny"}, w)
        cell = self.number(t, "cell_m", w, positive=True)
        g = Grid(x0_m=self.number(t, "x0_m", w, default=cell / 2), y0_m=self.number(t, "y0_m", w, default=cell / 2),
                 cell_m=cell, nx=self.integer(t, "nx", w), ny=self.integer(t, "ny", w))
        xmin, ymin, xmax, ymax = g.bounds()
        if xmin < -_EPS or ymin < -_EPS or xmax > room.width_m + _EPS or ymax > room.length_m + _EPS:
            raise self.fail(w, f"grid [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}] m is not inside the room "
                               f"[0, {room.width_m:g}] x [0, {room.length_m:g}] m",
                            "shrink nx/ny or cell_m, or move x0_m/y0_m (cell centres of the first cell)")
        return g

    def tx(self, t: dict, room: Room) -> TxSpec:
        w = "[tx]"
        allowed = {"position_m", "look_at_m", "num_rows", "num_cols", "pattern", "polarization", "power_dbm"}
        self.keys(t, allowed, {"position_m"}, w)
        pos = self.vec3(t, "position_m", w)
        if not (0 < pos[0] < room.width_m and 0 < pos[1] < room.length_m and 0 < pos[2] < room.height_m):
            raise self.fail(w, f"position_m {list(pos)} is outside the room "
                               f"(0..{room.width_m:g}, 0..{room.length_m:g}, 0..{room.height_m:g} m)",
                            "put the transmitter inside the room, e.g. just below the ceiling")
        look = self.vec3(t, "look_at_m", w) if "look_at_m" in t else None
        if look is not None and np.allclose(look, pos):
            raise self.fail(w, "look_at_m equals position_m", "point the array at another point, e.g. the floor")
        d = TxSpec(position_m=(0.0, 0.0, 0.0))
        return TxSpec(position_m=pos, look_at_m=look,
                      num_rows=self.integer(t, "num_rows", w, default=d.num_rows),
                      num_cols=self.integer(t, "num_cols", w, default=d.num_cols),
                      pattern=self.choice(t, "pattern", w, PATTERNS, default=d.pattern),
                      polarization=self.choice(t, "polarization", w, POLARIZATIONS, default=d.polarization),
                      power_dbm=self.number(t, "power_dbm", w, default=d.power_dbm))

    def obj(self, t: Any, where: str) -> Box:
        if not isinstance(t, dict):
            raise self.fail(where, "must be a table", "write it as an [[objects]] block")
        label = f"{where} {t['name']!r}" if isinstance(t.get("name"), str) else where
        self.keys(t, _OBJECT_KEYS, {"name", "kind", "x_m", "y_m"}, label)
        name = self.string(t, "name", label)
        if not _KIND_RE.match(name):
            raise self.fail(label, f"name {name!r} is not a valid object name",
                            "use lower-case letters, digits and '_' (e.g. 'chair_01')")
        kind = self.string(t, "kind", label)
        if not _KIND_RE.match(kind) or kind in ("floor", "ceiling"):
            raise self.fail(label, f"invalid kind {kind!r}",
                            "use lower-case letters, digits and '_'; floor and ceiling come from [room]")
        merged = {**self.kinds.get(kind, {}), **t}
        for key in ("material", "width_m", "length_m", "height_m"):
            if key not in merged:
                known = did_you_mean(kind, self.kinds)
                raise self.fail(label, f"missing field {key!r} (and no [kinds.{kind}] default)"
                                + (f"; kind {known}" if known and kind not in self.kinds else ""),
                                f"add `{key} = ...` to the object or to a [kinds.{kind}] table")
        return Box(name=name, kind=kind, material=self.material(merged, "material", label),
                   x_m=self.number(merged, "x_m", label), y_m=self.number(merged, "y_m", label),
                   width_m=self.number(merged, "width_m", label, positive=True),
                   length_m=self.number(merged, "length_m", label, positive=True),
                   height_m=self.number(merged, "height_m", label, positive=True),
                   z_m=self.number(merged, "z_m", label, default=0.0),
                   yaw_deg=self.number(merged, "yaw_deg", label, default=0.0))

    def dynamic(self, t: dict, objects: list[Box]) -> tuple[list[Box], str]:
        """Apply the [dynamic] changes in a fixed order: remove, move (in place), add (appended)."""
        w = "[dynamic]"
        self.keys(t, {"description", "add", "move", "remove"}, {"description"}, w)
        by_name = {b.name: i for i, b in enumerate(objects)}
        out: list[Box | None] = list(objects)
        remove = t.get("remove", [])
        if not isinstance(remove, list) or not all(isinstance(n, str) for n in remove):
            raise self.fail(w, "remove must be a list of object names", 'write `remove = ["chair_01"]`')
        for n in remove:
            if n not in by_name or out[by_name[n]] is None:
                raise self._unknown_object(f"{w} remove", n, by_name)
            out[by_name[n]] = None
        moves = t.get("move", [])
        if not isinstance(moves, list):
            raise self.fail(f"{w} move", "must be an array of tables", "write each change as a [[dynamic.move]] block")
        for i, m in enumerate(moves):
            where = f"dynamic.move[{i}]"
            if not isinstance(m, dict):
                raise self.fail(where, "must be a table", "write it as a [[dynamic.move]] block")
            self.keys(m, _MOVE_KEYS, {"name"}, where)
            n = self.string(m, "name", where)
            if n not in by_name or out[by_name[n]] is None:
                raise self._unknown_object(where, n, by_name)
            if len(m) == 1:
                raise self.fail(where, f"move of {n!r} changes nothing", "give at least one of x_m, y_m, z_m, yaw_deg")
            changes = {k: self.number(m, k, where) for k in m if k != "name"}
            out[by_name[n]] = replace(out[by_name[n]], **changes)
        adds = t.get("add", [])
        if not isinstance(adds, list):
            raise self.fail(f"{w} add", "must be an array of tables", "write each object as a [[dynamic.add]] block")
        added = [self.obj(a, f"dynamic.add[{i}]") for i, a in enumerate(adds)]
        summary = str(t["description"]).strip()
        return [b for b in out if b is not None] + added, summary

    def _unknown_object(self, where: str, name: str, by_name: dict) -> SceneFileError:
        close = did_you_mean(name, by_name)
        return self.fail(where, f"no blueprint object named {name!r}" + (f"; {close}" if close else ""),
                         "name an object from [[objects]]")

    def check_unique(self, boxes: list[Box]) -> None:
        seen: set[str] = set()
        for b in boxes:
            if b.name in seen:
                raise self.fail(f"object {b.name!r}", "duplicate name",
                                "give every object a unique name (walls/floor/ceiling names are reserved)")
            seen.add(b.name)

    def check_inside(self, b: Box, room: Room) -> None:
        c = b.corners()
        if (c[:, 0].min() < -_EPS or c[:, 1].min() < -_EPS or c[:, 0].max() > room.width_m + _EPS
                or c[:, 1].max() > room.length_m + _EPS):
            raise self.fail(f"object {b.name!r}",
                            f"footprint x {c[:, 0].min():.3f}..{c[:, 0].max():.3f}, y {c[:, 1].min():.3f}.."
                            f"{c[:, 1].max():.3f} m is outside the room "
                            f"[0, {room.width_m:g}] x [0, {room.length_m:g}] m",
                            "move it (x_m, y_m), shrink it, or change yaw_deg so it fits inside the walls")
        if b.z_m < -_EPS or b.top_m > room.height_m + _EPS:
            raise self.fail(f"object {b.name!r}", f"spans z {b.z_m:g}..{b.top_m:g} m, outside the room's "
                                                  f"0..{room.height_m:g} m", "fix z_m or height_m")
