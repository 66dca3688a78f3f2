"""The shape of a city scene file (TOML), as pydantic models, and pydantic's complaints in the file's own words.

A city is one file (``dallas.toml``, ``houston.toml`` beside this module are commented examples)::

    format = 1
    [scene]        name, title, description
    [city]         nw_lat_lon, se_lat_lon, crs, footprints, [ground_material, surface_material, surface_height_m]
    [grid]         cell_m
    [robot]        rx_height_m, robot_height_m
    [tx]           [num_rows, num_cols, pattern, polarization, power_dbm, clearance_m]
    [rt]           [samples_per_src, max_num_paths_per_src]      (instead of the indoor RTSettings defaults)
    [quadrants.qN] tx_m = [x, y, z]                      (N = 1..4; the paper's Tables III and IV)
    [dynamic]      quadrant, seed, cars, buses, roads = [{name, from_m, to_m}, ...] or "auto"
    [moving]       quadrant, description, [base, dt_s, horizon_s], [[moving.mover]] (vehicles driving along lanes:
                   :mod:`dtradar_data.scenes.moving_section`; read only for the moving twin,
                   :func:`~dtradar_data.scenes.city.reader.city_moving_scene`)

:func:`read_city_file` parses and validates a file into a :class:`CityDocument`; every mistake is a
:class:`~dtradar_data.core.errors.SceneFileError` naming the file, the section and the field (a misspelt key with
the keys it could be). The scenes a document makes, one per quadrant and variant, are built by
:mod:`dtradar_data.scenes.city.reader`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import tomllib
from pydantic import BaseModel, BeforeValidator, Field, ValidationError

from dtradar_data.core.errors import SceneFileError, did_you_mean
from dtradar_data.scenes.city.footprints import LonLatBox
from dtradar_data.scenes.fields import (
    Material,
    Num,
    Pos,
    PosInt,
    SceneFileModel,
    SceneName,
    Text,
)
from dtradar_data.scenes.model import PATTERNS, POLARIZATIONS
from dtradar_data.scenes.names import check_user_scene_name

FORMAT = 1


def _lat_lon(value: Any) -> tuple[float, float]:
    if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)):
        raise ValueError(f"must be [lat, lon] in degrees, got {value!r}")
    return float(value[0]), float(value[1])


def _vec(n: int):
    def check(value: Any) -> tuple[float, ...]:
        if not (
            isinstance(value, list)
            and len(value) == n
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        ):
            raise ValueError(f"must be a list of {n} numbers, got {value!r}")
        return tuple(float(v) for v in value)

    return check


LatLon = Annotated[tuple[float, float], BeforeValidator(_lat_lon)]
Vec2 = Annotated[tuple[float, float], BeforeValidator(_vec(2))]
Vec3 = Annotated[tuple[float, float, float], BeforeValidator(_vec(3))]


class CitySceneMeta(SceneFileModel):
    name: SceneName
    title: Text
    description: Text


class CitySection(SceneFileModel):
    nw_lat_lon: LatLon
    se_lat_lon: LatLon
    crs: Text
    footprints: Text
    ground_material: Material = "concrete"
    surface_material: Material = "concrete"
    surface_height_m: Pos = 0.02


class CityGrid(SceneFileModel):
    cell_m: Pos


class CityRobot(SceneFileModel):
    rx_height_m: Pos = 1.5
    robot_height_m: Pos = 1.5


class CityTx(SceneFileModel):
    num_rows: PosInt = 8
    num_cols: PosInt = 2
    pattern: Literal[PATTERNS] = "tr38901"  # type: ignore[valid-type]
    polarization: Literal[POLARIZATIONS] = "VH"  # type: ignore[valid-type]
    power_dbm: Num = 0.0
    clearance_m: Num = Field(default=3.0, ge=0)


class CityRt(SceneFileModel):
    """Ray-tracing settings the city needs instead of the (indoor) RTSettings defaults."""

    samples_per_src: PosInt | None = None
    max_num_paths_per_src: PosInt | None = None


class Quadrant(SceneFileModel):
    tx_m: Vec3
    more_tx_m: list[Vec3] = Field(default_factory=list, max_length=15)
    """Further transmitters of the quadrant (a deployment of several), each placed clear of the buildings as
    ``tx_m`` is; transmitter 0 is ``tx_m``."""


class RoadModel(SceneFileModel):
    name: Text
    from_m: Vec2
    to_m: Vec2


class CityDynamic(SceneFileModel):
    quadrant: Literal["q1", "q2", "q3", "q4"]
    seed: int = 0
    cars: int = Field(default=0, ge=0)
    buses: int = Field(default=0, ge=0)
    roads: list[RoadModel] | Literal["auto"] = "auto"


class CityDocument(SceneFileModel):
    format: Literal[1]
    scene: CitySceneMeta
    city: CitySection
    grid: CityGrid
    robot: CityRobot = CityRobot()
    tx: CityTx = CityTx()
    rt: CityRt = CityRt()
    quadrants: dict[Literal["q1", "q2", "q3", "q4"], Quadrant]
    dynamic: CityDynamic | None = None
    moving: dict[str, Any] | None = None
    """Checked only when the moving twin is read (:func:`city_moving_scene`), so it never touches the others."""

    @property
    def box(self) -> LonLatBox:
        return LonLatBox.from_corners(self.city.nw_lat_lon, self.city.se_lat_lon)


def read_city_file(path: str | Path) -> CityDocument:
    """Parse and validate a city scene file; :class:`SceneFileError` names the file, the section and the field."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise SceneFileError(
            f"{path}: cannot read city scene file ({getattr(e, 'strerror', None) or e})", hint="check the path"
        ) from e
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError(f"{path}: not valid TOML: {e}", hint="fix the syntax at the reported line") from e
    doc = parse_city(data, origin=str(path))
    check_user_scene_name(doc.scene.name, path, derived=tuple(f"{doc.scene.name}-{q}" for q in sorted(doc.quadrants)))
    return doc


def parse_city(data: dict[str, Any], *, origin: str = "<city>") -> CityDocument:
    if isinstance(data.get("tx"), list):  # the quadrants place the arrays; [tx] is what they share
        raise SceneFileError(
            f"{origin}: [[tx]] (an array of tables): a city's [tx] is the one array every transmitter of it has",
            hint="write [tx] once; place a quadrant's transmitters with [quadrants.qN] tx_m (and more_tx_m)",
        )
    try:
        return CityDocument.model_validate(data)
    except ValidationError as exc:
        errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
        e = errors[0]
        loc = [str(p) for p in e["loc"] if not (isinstance(p, str) and ("[" in p or p.startswith("function")))]
        where = f"[{'.'.join(loc[:-1])}]" if len(loc) > 1 else "top level"
        field = loc[-1] if loc else "(document)"
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        if e["type"] == "extra_forbidden":
            allowed = _allowed_keys(loc[:-1])
            close = did_you_mean(field, allowed)
            raise SceneFileError(
                f"{origin}: {where}: unknown key {field!r}" + (f"; {close}" if close else "") + more,
                hint="allowed keys: " + ", ".join(allowed),
            ) from exc
        if e["type"] == "missing":
            raise SceneFileError(
                f"{origin}: {where}: missing {'section' if len(loc) == 1 else 'field'} {field!r}" + more,
                hint="see dtradar_data/scenes/city/dallas.toml for the expected form",
            ) from exc
        msg = e["msg"].removeprefix("Value error, ")
        hint = e.get("ctx", {}).get("hint") or "see dtradar_data/scenes/city/dallas.toml for the expected form"
        raise SceneFileError(f"{origin}: {where}: {field}: {msg}" + more, hint=hint) from exc


def _allowed_keys(loc: list[str]) -> list[str]:
    model: Any = CityDocument
    for part in loc:
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            break
        ann = field.annotation
        model = next(
            (a for a in getattr(ann, "__args__", (ann,)) if isinstance(a, type) and issubclass(a, BaseModel)), ann
        )
    return sorted(getattr(model, "model_fields", {}))
