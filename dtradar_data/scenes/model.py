"""The scene model: one variant of one digital twin as frozen, validated data.

A :class:`SceneSpec` holds the receiver grid, the transmitter, the robot's heights and the objects: boxes as the paper
describes obstacles, ``(x, y, height, width, length)`` with a yaw about +z, a bottom height ``z`` and an ITU material
(walls, floor and ceiling slabs of a room, and a city's ground, are boxes too; a box may be drawn with a bundled mesh,
such as Sionna's low-poly car, scaled into it), and, for city twins, :class:`Prism` objects: footprint polygons
extruded vertically (buildings, and thin parking-lot and road surfaces). Readers (:mod:`dtradar_data.scenes.indoor`
for the TOML room files, :mod:`dtradar_data.scenes.city` for city scene files) build specs; geometry, ray tracing and
the store consume them. Its :meth:`SceneSpec.digest` identifies the
scene in dataset versions, so its canonical JSON must not change for an unchanged scene.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from dtradar_data.core.grid import Grid

STRUCTURE_KINDS = ("wall", "floor", "ceiling")  # generated from [room]; walls also obstruct the robot
PATTERNS = ("iso", "dipole", "hw_dipole", "tr38901")
POLARIZATIONS = ("V", "H", "VH", "cross")
#: Ray-tracing settings of outdoor scenes instead of the (indoor) RTSettings defaults: paths are ~20x longer and the
#: default 1e6 path buffer loses half of them (measured on Dallas Q3, README "Benchmarks"). City scene files repeat
#: them in their [rt] section; Sionna's bundled cities use them.
OUTDOOR_RT_DEFAULTS: dict[str, int] = {"samples_per_src": 100_000, "max_num_paths_per_src": 10_000_000}


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
    mesh: str | None = None
    """A bundled mesh drawn scaled into the box instead of the box itself (``"sionna:low_poly_car"``); the box stays
    its footprint for occupancy."""

    @property
    def top_m(self) -> float:
        return self.z_m + self.height_m

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if self.mesh is None:  # keep the canonical JSON (and the digests) of scenes written before meshes existed
            d.pop("mesh")
        return d

    def corners(self) -> np.ndarray:
        """Footprint corners, float64[4, 2], counter-clockwise."""
        hw, hl = self.width_m / 2, self.length_m / 2
        local = np.array([[-hw, -hl], [hw, -hl], [hw, hl], [-hw, hl]])
        t = math.radians(self.yaw_deg)
        rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
        return local @ rot.T + np.array([self.x_m, self.y_m])


Ring = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Prism:
    """A footprint polygon extruded from ``z_m`` to ``z_m + height_m``: a building, or a thin parking-lot or road
    surface. Rings are in scene metres and not closed; the exterior is counter-clockwise, holes clockwise."""

    name: str
    kind: str
    material: str
    exterior: Ring
    height_m: float
    holes: tuple[Ring, ...] = ()
    z_m: float = 0.0

    @property
    def top_m(self) -> float:
        return self.z_m + self.height_m

    def bounds(self) -> tuple[float, float, float, float]:
        xs, ys = zip(*self.exterior)
        return min(xs), min(ys), max(xs), max(ys)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "material": self.material,
            "exterior": [list(p) for p in self.exterior],
            "holes": [[list(p) for p in h] for h in self.holes],
            "height_m": self.height_m,
            "z_m": self.z_m,
        }


@dataclass(frozen=True)
class MeshScene:
    """A Mitsuba/Sionna XML scene a spec is built on (Sionna's bundled Munich, or a user's file): its shapes are
    traced as they are, the spec's own boxes and prisms are added on top. Identified by content, not by location."""

    xml: str
    """``"sionna:munich"`` for a scene bundled with sionna-rt, else the XML file's name."""
    sha256: str
    """sha256 of the XML and of every mesh file it references, in order: a changed file changes the digest."""
    ground: tuple[str, ...] = ()
    """Ids of the shapes that are the ground (or terrain): they carry the robot and never block it."""
    path: str = field(default="", compare=False)
    """Where the XML is on this machine; not in the digest, so a moved file keeps its dataset version."""

    def to_dict(self) -> dict[str, Any]:
        return {"xml": self.xml, "sha256": self.sha256, "ground": list(self.ground)}


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
    orientation_deg: tuple[float, float, float] | None = None
    """The array's orientation as Sionna's (yaw about z, pitch about y, roll about x) in degrees; when set it orients
    the array instead of ``look_at_m`` (which then only records where the boresight points). Set by an
    antenna-pose-error twin (:mod:`dtradar_data.scenes.tx_pose`), whose turn a look-at point cannot express."""
    name: str | None = None
    """The scene file's name for the transmitter (``[[tx]] name``), shown by the dataset card; None for a twin's only
    transmitter, whose digest predates names."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-able; ``orientation_deg`` and ``name`` only when set, so the digests of scenes written before them stay
        valid."""
        d = asdict(self)
        if self.name is None:
            d.pop("name")
        d["position_m"] = list(self.position_m)
        d["look_at_m"] = None if self.look_at_m is None else list(self.look_at_m)
        if self.orientation_deg is None:
            d.pop("orientation_deg")
        else:
            d["orientation_deg"] = list(self.orientation_deg)
        return d


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
    prisms: tuple[Prism, ...] = ()
    base: MeshScene | None = None
    """An external Mitsuba/Sionna XML scene the objects are added to (:mod:`dtradar_data.scenes.xml_scene`)."""
    provenance: dict[str, Any] = field(default_factory=dict, compare=False)
    """Where the geometry came from (a city's footprint source, download time, processing report). Recorded in the
    dataset's metadata, not in the digest: the geometry itself is."""
    rt_defaults: dict[str, Any] = field(default_factory=dict, compare=False)
    """Ray-tracing settings this scene needs instead of the indoor defaults (a city's ``[rt]`` section: outdoor paths
    are 20x longer). Not in the digest: the settings used are hashed into the version anyway."""
    more_tx: tuple[TxSpec, ...] = ()
    """Transmitters 1..K-1 of a twin with several (a scene file's further ``[[tx]]`` tables); ``tx`` is transmitter 0.
    One trace covers all of them; transmitter k's radio columns are ``tx{k}_<name>`` in the cell table."""

    @property
    def transmitters(self) -> tuple[TxSpec, ...]:
        """Every transmitter, ``tx`` first."""
        return (self.tx, *self.more_tx)

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.variant}"

    def obstacles(self) -> tuple[Box, ...]:
        """Objects that can obstruct the robot: everything except floor and ceiling slabs."""
        return tuple(b for b in self.objects if b.kind not in ("floor", "ceiling"))

    def count_by_kind(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for b in (*self.objects, *self.prisms):
            counts[b.kind] = counts.get(b.kind, 0) + 1
        return counts

    def to_dict(self) -> dict[str, Any]:
        """JSON-able and canonical: tuples become lists, key order is fixed by :meth:`digest`'s ``sort_keys``.
        Fields added after the indoor twins (prisms, base) appear only when used, so older digests stay valid."""
        d = asdict(self)
        d.pop("provenance")
        d.pop("rt_defaults")
        d["objects"] = [b.to_dict() for b in self.objects]
        if self.prisms:
            d["prisms"] = [p.to_dict() for p in self.prisms]
        else:
            d.pop("prisms")
        if self.base is not None:
            d["base"] = self.base.to_dict()
        else:
            d.pop("base")
        d["tx"] = self.tx.to_dict()
        if self.more_tx:  # only when used: the digests of one-transmitter scenes stay valid
            d["more_tx"] = [t.to_dict() for t in self.more_tx]
        else:
            d.pop("more_tx")
        return d

    def canonical_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)

    def digest(self) -> str:
        """sha256 hex of the canonical JSON: equal specs, equal digests, whatever file they were read from."""
        return hashlib.sha256(self.canonical_json().encode("ascii")).hexdigest()
