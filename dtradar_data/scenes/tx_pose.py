"""An antenna-pose-error twin: the same scene with its transmitter a little off where the twin has it.

A robot that navigates by radio is trained on a twin whose transmitter pose came from the twin; the real access
point is never exactly there. :func:`tx_pose_error` makes the twin to evaluate that on: the transmitter moved by
exactly ``offset_m`` in a seeded horizontal direction (height kept) and its antenna array turned by exactly
``angle_deg`` about a seeded axis perpendicular to its boresight (a ceiling access point pointing straight down is
tilted, a street-level one is turned). Everything else (grid, objects, materials, heights, ray-tracing defaults) is
unchanged, and the scene is renamed ``<scene>-txpose`` (:data:`~dtradar_data.core.ids.TX_POSE_SUFFIX`), so the
twin is stored as its own dataset and never becomes a version of the original.

The turn is exact for the whole array, not only for its boresight: the new orientation is the old one rotated by
``angle_deg`` about the axis (``TxSpec.orientation_deg``). A look-at point alone cannot say that, since Sionna
derives the roll from it: a boresight tilted 5 degrees off the vertical would also spin the array about the vertical
by the azimuth of the tilt. ``look_at_m`` is set too, at the original distance along the new boresight, so the spec
still says where the array points.

The direction of the move is drawn from ``numpy.random.default_rng(seed)`` after the axis; a direction that would put
the transmitter outside the room (indoors) or inside an object or building is skipped for the next one (the shapes
of an XML scene's own mesh, such as Sionna's Munich, are checked only when the twin is built, by
:func:`~dtradar_data.geometry.xml_transmitter.check_transmitter_in_mesh`, which refuses a move into a building).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError
from dtradar_data.core.ids import TX_POSE_SUFFIX
from dtradar_data.scenes.model import SceneSpec, TxSpec
from dtradar_data.scenes.transmitters import object_at

__all__ = [
    "TX_POSE_SUFFIX",
    "MAX_TRIES",
    "check_tx_pose_error",
    "is_tx_pose_scene",
    "orientation_matrix",
    "tx_orientation_deg",
    "tx_pose_error",
]

MAX_TRIES = 64
"""Seeded directions tried before a move that always leaves the room (or ends inside an object) is an error."""
DIGITS = 6
"""Positions (m) and angles (deg) of the new pose are rounded to this many decimals, so the spec's digest does not
depend on the last bits of a platform's trigonometry; the offset and the angle stay exact to about 1e-6."""


def is_tx_pose_scene(scene: str) -> bool:
    """Whether a dataset scene name is that of an antenna-pose-error twin (``cubicle-txpose``)."""
    return scene.endswith(TX_POSE_SUFFIX)


def check_tx_pose_error(offset_m: float, angle_deg: float, seed: int = 0) -> None:
    """:class:`InvalidSettingError` unless ``0 <= offset_m`` (finite) and ``0 <= angle_deg < 90``."""
    flag = "--tx-pose-error OFFSET_M ANGLE_DEG"
    if isinstance(offset_m, bool) or not isinstance(offset_m, (int, float)) or not math.isfinite(offset_m):
        raise InvalidSettingError(f"{flag}: offset {offset_m!r} is not a finite number of metres", hint="e.g. 0.5")
    if offset_m < 0:
        raise InvalidSettingError(
            f"{flag}: offset {offset_m} m is negative",
            hint="give a distance >= 0; the direction is drawn from the seed",
        )
    if isinstance(angle_deg, bool) or not isinstance(angle_deg, (int, float)) or not math.isfinite(angle_deg):
        raise InvalidSettingError(f"{flag}: angle {angle_deg!r} is not a finite number of degrees", hint="e.g. 5")
    if not 0 <= angle_deg < 90:
        raise InvalidSettingError(
            f"{flag}: angle {angle_deg} deg is outside [0, 90)",
            hint="give a turn of the boresight in degrees, >= 0 and < 90 (the axis is drawn from the seed)",
        )
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InvalidSettingError(f"--tx-pose-seed {seed!r} must be an integer >= 0", hint="e.g. 0")


# ------------------------------------------------------------------------------------------- orientation
def orientation_matrix(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Sionna's rotation of a radio device, ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``: column 0 is the boresight."""
    a, b, c = (math.radians(v) for v in (yaw_deg, pitch_deg, roll_deg))
    rz = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0], [-math.sin(b), 0.0, math.cos(b)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(c), -math.sin(c)], [0.0, math.sin(c), math.cos(c)]])
    return rz @ ry @ rx


def _euler_deg(r: np.ndarray) -> tuple[float, float, float]:
    """The inverse of :func:`orientation_matrix` (yaw, pitch in [-90, 90], roll); roll 0 at gimbal lock."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if math.cos(pitch) < 1e-9:  # boresight vertical: only yaw - roll (or + roll) is defined
        return math.degrees(math.atan2(-r[0, 1], r[1, 1])), math.degrees(pitch), 0.0
    return (
        math.degrees(math.atan2(r[1, 0], r[0, 0])),
        math.degrees(pitch),
        math.degrees(math.atan2(r[2, 1], r[2, 2])),
    )


def tx_orientation_deg(tx: TxSpec) -> tuple[float, float, float]:
    """The orientation Sionna gives ``tx``: its ``orientation_deg``, else the one ``look_at_m`` sets (azimuth and
    zenith of the direction, no roll; azimuth 0 for a vertical direction, as Sionna does), else (0, 0, 0), which
    points the boresight along +x."""
    if tx.orientation_deg is not None:
        return tuple(float(v) for v in tx.orientation_deg)  # type: ignore[return-value]
    if tx.look_at_m is None:
        return (0.0, 0.0, 0.0)
    d = np.subtract(tx.look_at_m, tx.position_m, dtype=float)
    norm = float(np.linalg.norm(d))
    if norm == 0:
        raise InvalidCoordinatesError(
            f"the transmitter's look_at_m {tx.look_at_m} equals its position", hint="point it at another point"
        )
    d /= norm
    rho = math.hypot(d[0], d[1])
    theta = math.atan2(rho, d[2])
    phi = 0.0 if rho < 1e-9 else math.atan2(d[1], d[0])
    return (math.degrees(phi), math.degrees(theta) - 90.0, 0.0)


def _rotate(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle_rad`` about the unit vector ``axis``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * (k @ k)


# ------------------------------------------------------------------------------------------- free space
def _why_not(spec: SceneSpec, p: np.ndarray) -> str | None:
    """Why the transmitter cannot stand at ``p``: outside the room, or inside an object; None if it can."""
    if spec.room is not None and not (0 < p[0] < spec.room.width_m and 0 < p[1] < spec.room.length_m):
        return f"outside the room [0, {spec.room.width_m:g}] x [0, {spec.room.length_m:g}] m"
    inside = object_at(spec, p)
    return f"inside {inside!r}" if inside else None


# ------------------------------------------------------------------------------------------- the twin
def tx_pose_error(spec: SceneSpec, *, offset_m: float = 0.5, angle_deg: float = 5.0, seed: int = 0) -> SceneSpec:
    """``spec`` with its transmitter moved by exactly ``offset_m`` horizontally and turned by exactly ``angle_deg``,
    named ``<scene>-txpose``; seeded and repeatable (the same seed gives the same pose for every variant of a scene).

    Raises :class:`InvalidSettingError` for a negative or non-finite offset or angle, an angle of 90 degrees or more,
    or a spec that already is a pose twin; :class:`InvalidCoordinatesError` when no seeded direction keeps the
    transmitter inside the room and out of every object.
    """
    check_tx_pose_error(offset_m, angle_deg, seed)
    _refuse_a_pose_twin(spec)
    if spec.more_tx:  # which of them would be off, and by one draw or one each, is not settled
        raise InvalidSettingError(
            f"--tx-pose-error: {spec.name} has {len(spec.transmitters)} transmitters, and a pose error is drawn "
            "for a twin with one in this version",
            hint="drop --tx-pose-error, or build the pose twin of a one-transmitter scene",
        )
    pose = _draw_pose(spec, offset_m, angle_deg, seed)
    record = _record(spec, offset_m, angle_deg, seed, pose)
    return dataclasses.replace(
        spec,
        scene=spec.scene + TX_POSE_SUFFIX,
        title=f"{spec.title}, transmitter {offset_m:g} m and {angle_deg:g} deg off",
        description=_description(spec, offset_m, angle_deg, seed, pose, record["move_azimuth_deg"]),
        tx=dataclasses.replace(
            spec.tx, position_m=pose.position, look_at_m=pose.look_at, orientation_deg=pose.orientation
        ),
        provenance={**spec.provenance, "tx_pose_error": record},
    )


@dataclasses.dataclass(frozen=True)
class _Pose:
    """The perturbed transmitter (rounded to :data:`DIGITS`) and the draws that made it."""

    position: tuple[float, ...]
    look_at: tuple[float, ...]
    orientation: tuple[float, ...]
    boresight: np.ndarray
    axis: np.ndarray
    direction: float
    directions_tried: int


def _refuse_a_pose_twin(spec: SceneSpec) -> None:
    """A pose twin of a pose twin would stack two errors under one name: refused, pointing at the original."""
    if is_tx_pose_scene(spec.scene):
        raise InvalidSettingError(
            f"{spec.name} already is an antenna-pose-error twin",
            hint=f"apply the pose error to the original scene {spec.scene.removesuffix(TX_POSE_SUFFIX)!r}",
        )


def _draw_pose(spec: SceneSpec, offset_m: float, angle_deg: float, seed: int) -> _Pose:
    """The seeded new pose: the turn's axis is drawn first, then the move's directions, from one generator (the
    order is part of what a seed means)."""
    tx = spec.tx
    pos0 = np.asarray(tx.position_m, dtype=float)
    r0 = orientation_matrix(*tx_orientation_deg(tx))
    rng = np.random.default_rng(seed)
    axis, orientation, boresight1 = _turn(r0, angle_deg, rng)
    direction, pos1, tried = _move(spec, pos0, offset_m, rng)
    position = tuple(round(float(v), DIGITS) for v in pos1)
    # the look-at keeps its distance along the new boresight, so the spec still says where the array points
    distance = float(np.linalg.norm(np.subtract(tx.look_at_m, pos0))) if tx.look_at_m is not None else 1.0
    look_at = tuple(round(float(v), DIGITS) for v in np.asarray(position) + distance * boresight1)
    return _Pose(position, look_at, orientation, boresight1, axis, direction, tried)


def _turn(r0: np.ndarray, angle_deg: float, rng: np.random.Generator) -> tuple[np.ndarray, tuple, np.ndarray]:
    """The turn's axis, the new orientation (rounded) and its boresight: about a seeded axis in the plane
    perpendicular to the boresight (spanned by the array's local y, z)."""
    psi = float(rng.uniform(0.0, 2 * math.pi))
    axis = math.cos(psi) * r0[:, 1] + math.sin(psi) * r0[:, 2]
    r1 = _rotate(axis, math.radians(angle_deg)) @ r0
    orientation = tuple(round(v, DIGITS) for v in _euler_deg(r1))
    # the boresight of the rounded orientation, the one the spec will hold
    return axis, orientation, orientation_matrix(*orientation)[:, 0]


def _move(
    spec: SceneSpec, pos0: np.ndarray, offset_m: float, rng: np.random.Generator
) -> tuple[float, np.ndarray, int]:
    """The first seeded horizontal direction that keeps the transmitter in free space: the direction, the new
    position and how many directions were tried; :class:`InvalidCoordinatesError` after :data:`MAX_TRIES`."""
    rejected: list[str] = []
    for _ in range(MAX_TRIES):
        direction = float(rng.uniform(0.0, 2 * math.pi))
        pos1 = pos0 + offset_m * np.array([math.cos(direction), math.sin(direction), 0.0])
        why = _why_not(spec, pos1)
        if why is None:
            return direction, pos1, len(rejected) + 1
        rejected.append(why)
    raise InvalidCoordinatesError(
        f"{spec.name}: moving the transmitter {offset_m:g} m from {tuple(pos0.round(3))} puts it "
        f"{rejected[0]} (and in {MAX_TRIES - 1} more seeded directions)",
        hint="use a smaller offset (--tx-pose-error OFFSET_M ANGLE_DEG) or move the transmitter in the scene file",
    )


def _record(spec: SceneSpec, offset_m: float, angle_deg: float, seed: int, pose: _Pose) -> dict[str, Any]:
    """The provenance of the twin: the settings, the draws, and the original and perturbed poses side by side."""
    tx = spec.tx
    boresight0 = orientation_matrix(*tx_orientation_deg(tx))[:, 0]
    return {
        "scene": spec.scene,
        "offset_m": float(offset_m),
        "angle_deg": float(angle_deg),
        "seed": int(seed),
        "move_azimuth_deg": round(math.degrees(pose.direction) % 360.0, DIGITS),
        "directions_tried": pose.directions_tried,
        "turn_axis": [round(float(v), DIGITS) for v in pose.axis],
        "original": {
            "position_m": list(tx.position_m),
            "look_at_m": None if tx.look_at_m is None else list(tx.look_at_m),
            "orientation_deg": [round(v, DIGITS) for v in tx_orientation_deg(tx)],
            "boresight": [round(float(v), DIGITS) for v in boresight0],
        },
        "perturbed": {
            "position_m": list(pose.position),
            "look_at_m": list(pose.look_at),
            "orientation_deg": list(pose.orientation),
            "boresight": [round(float(v), DIGITS) for v in pose.boresight],
        },
    }


def _description(spec: SceneSpec, offset_m: float, angle_deg: float, seed: int, pose: _Pose, azimuth_deg: float) -> str:
    """The twin's description: the original's, then what was moved and turned, from where to where."""
    tx = spec.tx
    was = "Sionna's default orientation (boresight +x)" if tx.look_at_m is None else f"looking at {_fmt(tx.look_at_m)}"
    return (
        f"{spec.description} Antenna-pose-error twin of {spec.name}: the transmitter is moved {offset_m:g} m "
        f"horizontally (towards azimuth {azimuth_deg:.1f} deg) from {_fmt(tx.position_m)} to "
        f"{_fmt(pose.position)} m, and its antenna array, {was}, is turned {angle_deg:g} deg about an axis "
        f"perpendicular to its boresight, to look at {_fmt(pose.look_at)} (orientation {_fmt(pose.orientation)} deg); "
        f"seed {seed}. Everything else is the original twin."
    )


def _fmt(v) -> str:
    return "(" + ", ".join(f"{round(float(x), 3) + 0.0:g}" for x in v) + ")"
