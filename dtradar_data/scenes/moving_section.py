"""The ``[moving]`` section of a scene file (TOML), read into a :class:`~dtradar_data.scenes.moving_scene.MovingScene`.

Only the variant ``"moving"`` reads the section (:func:`moving_scene_from_section`, called by the indoor and city
readers), so the blueprint and dynamic twins of a file never see it. Each ``[[moving.mover]]`` table becomes a
:class:`~dtradar_data.scenes.mover.Mover`, its size, material and mesh defaulting to :data:`MOVER_KINDS` for a known
kind; the step defaults to ``cell_m / ROBOT_SPEED_MPS`` and the horizon to the movers' common period. Every mistake
is a :class:`~dtradar_data.core.errors.SceneFileError` that names the file, the mover and the key, with a fix.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any

from pydantic import BeforeValidator, ValidationError

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.city.streets import VEHICLES
from dtradar_data.scenes.fields import (
    Material,
    ObjName,
    SceneFileModel,
    Text,
    choice,
    fail,
)
from dtradar_data.scenes.model import SceneSpec
from dtradar_data.scenes.mover import MODES, MOVER_MESHES, Mover, is_finite
from dtradar_data.scenes.moving_scene import (
    BASE_VARIANTS,
    DEFAULT_MAX_SNAPSHOTS,
    ROBOT_SPEED_MPS,
    MovingScene,
    common_snapshots,
)

__all__ = ["MOVER_KINDS", "moving_scene_from_section"]

#: Default size and look of a mover of a known kind: (width_m along its direction of travel, length_m across it,
#: height_m, material, mesh). A person as the dynamic twins' people (0.3 m chest to back, 0.5 m shoulders, 1.75 m,
#: ITU "wet_ground" standing in for tissue: cubicle.toml says why); cars and buses as the dynamic city twin's.
MOVER_KINDS: dict[str, tuple[float, float, float, str, str | None]] = {
    "person": (0.3, 0.5, 1.75, "wet_ground", None),
    **VEHICLES,  # (length, width, ...): a vehicle's length is along its way, its box's width_m
}


def _positive_seconds(what: str, example: str):
    def check(value: Any) -> float:
        if not is_finite(value) or value <= 0:
            raise fail(f"must be a finite number of seconds > 0, got {value!r}", f"write e.g. `{what} = {example}`")
        return float(value)

    return check


def _finite_number(value: Any) -> float:
    if not is_finite(value):
        raise fail(f"must be a finite number, got {value!r}", "write a number, e.g. `0.0`")
    return float(value)


def _positive_number(what: str, example: str):
    def check(value: Any) -> float:
        if not is_finite(value) or value <= 0:
            raise fail(f"must be a finite number > 0, got {value!r}", f"write e.g. `{what} = {example}`")
        return float(value)

    return check


def _waypoints(value: Any) -> tuple[tuple[float, float], ...]:
    example = "write `waypoints = [[1.0, 2.0], [5.0, 2.0]]` (x, y in scene metres)"
    if not isinstance(value, list):
        raise fail(f"must be an array of [x, y] points, got {value!r}", example)
    if len(value) < 2:
        raise fail(f"has {len(value)} point{'s' * (len(value) != 1)}: a mover needs at least 2", example)
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 2 and all(is_finite(v) for v in p)):
            raise fail(f"[{i}] = {p!r} is not a point [x, y] of two finite numbers", example)
    return tuple((float(p[0]), float(p[1])) for p in value)


class MoverModel(SceneFileModel):
    """One ``[[moving.mover]]`` table; sizes, material and mesh default to :data:`MOVER_KINDS` for a known kind."""

    name: ObjName
    kind: ObjName
    speed_mps: Annotated[float, BeforeValidator(_positive_number("speed_mps", "1.0"))]
    waypoints: Annotated[tuple[tuple[float, float], ...], BeforeValidator(_waypoints)]
    mode: Annotated[str, BeforeValidator(choice(MODES, "a mode"))] = "loop"
    start_offset_s: Annotated[float, BeforeValidator(_finite_number)] = 0.0
    material: Material | None = None
    width_m: Annotated[float | None, BeforeValidator(_positive_number("width_m", "0.3"))] = None
    length_m: Annotated[float | None, BeforeValidator(_positive_number("length_m", "0.5"))] = None
    height_m: Annotated[float | None, BeforeValidator(_positive_number("height_m", "1.75"))] = None
    mesh: Annotated[str | None, BeforeValidator(choice(MOVER_MESHES, "a bundled mesh"))] = None


class MovingModel(SceneFileModel):
    """The ``[moving]`` section (a city file's ``quadrant`` is taken out by its reader first)."""

    description: Text
    base: Annotated[str, BeforeValidator(choice(BASE_VARIANTS, "a base variant"))] = "blueprint"
    dt_s: Annotated[float | None, BeforeValidator(_positive_seconds("dt_s", "1.0"))] = None
    horizon_s: Annotated[float | None, BeforeValidator(_positive_seconds("horizon_s", "60.0"))] = None
    mover: list[dict[str, Any]] = []


_MOVER_KEYS = tuple(MoverModel.model_fields)
_MOVING_KEYS = tuple(MovingModel.model_fields)


def _raise_first(exc: ValidationError, origin: str, where: str, allowed: tuple[str, ...]) -> None:
    """The first pydantic complaint about a [moving] table, in the file's words (misspelt keys first)."""
    errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
    e = errors[0]
    loc = [p for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function")))]
    key = next((str(p) for p in loc if isinstance(p, str)), "(table)")
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    if e["type"] == "extra_forbidden":
        close = did_you_mean(key, allowed)
        raise SceneFileError(
            f"{origin}: {where}: unknown key {key!r}" + (f"; {close}" if close else "") + more,
            hint="allowed keys: " + ", ".join(allowed),
        ) from None
    if e["type"] == "missing":
        raise SceneFileError(f"{origin}: {where}: missing field {key!r}" + more, hint=f"add `{key} = ...`") from None
    if e["type"] == "dtradar":
        raise SceneFileError(f"{origin}: {where}: {key} {e['ctx']['problem']}" + more, hint=e["ctx"]["hint"]) from None
    raise SceneFileError(
        f"{origin}: {where}: {key}: {e['msg']}" + more, hint="see the [moving] section of cubicle.toml"
    ) from None


def _mover(raw: Any, i: int, origin: str) -> Mover:
    where = f"moving.mover[{i}]"
    if not isinstance(raw, dict):
        raise SceneFileError(f"{origin}: {where}: must be a table", hint="write it as a [[moving.mover]] block")
    if isinstance(raw.get("name"), str):
        where += f" {raw['name']!r}"
    try:
        m = MoverModel.model_validate(raw)
    except ValidationError as exc:
        _raise_first(exc, origin, where, _MOVER_KEYS)
    given = m.model_dump(include={"width_m", "length_m", "height_m", "material", "mesh"}, exclude_none=True)
    if m.kind in MOVER_KINDS:
        width, length, height, material, mesh = MOVER_KINDS[m.kind]
        values = {"width_m": width, "length_m": length, "height_m": height, "material": material, "mesh": mesh}
        values |= given
    else:
        values = {"mesh": None} | given
        missing = [k for k in ("width_m", "length_m", "height_m", "material") if k not in values]
        if missing:
            close = did_you_mean(m.kind, MOVER_KINDS)
            raise SceneFileError(
                f"{origin}: {where}: kind {m.kind!r} has no default size, and the mover does not give "
                + ", ".join(missing)
                + (f"; {close}" if close else ""),
                hint="give width_m (along its way), length_m (across), height_m and material, or use a kind with "
                "defaults: " + ", ".join(MOVER_KINDS),
            )
    try:
        return Mover(
            name=m.name,
            kind=m.kind,
            speed_mps=m.speed_mps,
            waypoints=m.waypoints,
            mode=m.mode,
            start_offset_s=m.start_offset_s,
            **values,
        )
    except SceneFileError as e:
        raise SceneFileError(f"{origin}: {where}: {e.message.partition(': ')[2]}", hint=e.hint) from None


def moving_scene_from_section(
    section: Any,
    base_spec: Callable[[str], SceneSpec],
    *,
    origin: str,
    title: str,
    description: str,
) -> MovingScene:
    """The moving twin a file's ``[moving]`` section declares: ``base_spec(variant)`` builds the base variant
    (``base = "blueprint"`` by default), ``title`` is the twin's, ``description`` the scene's (the section's own is
    appended). Every problem is a :class:`SceneFileError` naming ``origin`` and the mover."""
    if not isinstance(section, dict):
        raise SceneFileError(f"{origin}: [moving] must be a table", hint="write key = value lines under [moving]")
    try:
        model = MovingModel.model_validate(section)
    except ValidationError as exc:
        _raise_first(exc, origin, "[moving]", _MOVING_KEYS)
    movers = tuple(_mover(raw, i, origin) for i, raw in enumerate(model.mover))
    base = base_spec(model.base)
    if base.more_tx:  # the moving tables and their differential snapshots are one transmitter's, for now
        raise SceneFileError(
            f"{origin}: [moving]: the {model.base} twin has {len(base.transmitters)} transmitters, and a moving twin "
            "has one in this version",
            hint="build the moving twin from a scene file with one [tx]; the static twins take several",
        )
    dt_s = model.dt_s if model.dt_s is not None else base.grid.cell_m / ROBOT_SPEED_MPS
    if model.horizon_s is not None:
        snapshots = round(model.horizon_s / dt_s)
        if snapshots < 1:
            raise SceneFileError(
                f"{origin}: [moving]: horizon_s = {model.horizon_s:g} is shorter than one step (dt_s = {dt_s:g} s)",
                hint=f"give horizon_s of at least {dt_s:g} s, or drop it for the movers' common period",
            )
        how = "scene file"
    else:
        snapshots = common_snapshots(movers, dt_s) if movers else 1
        exact = movers and math.lcm(*(max(1, round(m.period_s / dt_s)) for m in movers)) <= DEFAULT_MAX_SNAPSHOTS
        how = "common period" if exact else f"capped at {DEFAULT_MAX_SNAPSHOTS} snapshots"
    provenance = {
        "base": model.base,
        "dt_s": dt_s,
        "dt_from": "scene file" if model.dt_s is not None else f"cell_m / {ROBOT_SPEED_MPS} m/s",
        "snapshots": snapshots,
        "horizon_from": how,
    }
    try:
        return MovingScene(
            base=base,
            movers=movers,
            dt_s=dt_s,
            snapshots=snapshots,
            title=title,
            description=f"{description}\n\nMoving twin ({model.base} + {len(movers)} movers): {model.description}",
            provenance=provenance,
        )
    except SceneFileError as e:
        raise SceneFileError(f"{origin}: [moving] {e.message}", hint=e.hint) from None
