"""The version record: what ``meta.json`` (and the Parquet schema metadata) says about one stored dataset version.

One typed model instead of free-form dicts read with ``.get`` fallbacks. On disk it stays the same JSON object, so
older releases of this package read new records (they ignore the keys they do not know) and this one reads old
records: :meth:`VersionRecord.from_meta` migrates a record without ``record_format`` (format 0, before the record
was typed, when the scene's title, licence or grid could live only inside ``scene_spec``) in one place. A record of a
newer format than this package knows is refused with a typed error saying to upgrade.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dtradar_data.core.errors import CorruptDatasetError

RECORD_FORMAT = 1
#: keys that a format-0 record may carry only inside its ``scene_spec`` (name in the record, name in the spec)
_FROM_SPEC = (
    ("title", "title"),
    ("description", "description"),
    ("source", "source"),
    ("licence", "licence"),
    ("attribution", "attribution"),
    ("grid", "grid"),
    ("transmitter", "tx"),
    ("rx_height_m", "rx_height_m"),
    ("robot_height_m", "robot_height_m"),
)


class FileRecord(BaseModel):
    model_config = ConfigDict(frozen=True)

    sha256: str
    bytes: int = Field(ge=0)


class VersionRecord(BaseModel):
    """One stored version. Unknown keys are kept (``extra='allow'``): a city build records its footprint report."""

    model_config = ConfigDict(extra="allow", frozen=True)

    record_format: int = RECORD_FORMAT
    name: str
    scene: str
    variant: str
    version: str
    schema_version: int
    created_utc: str | None = None
    title: str = ""
    description: str = ""
    source: str = ""
    licence: str = ""
    attribution: str = ""
    scene_spec: dict[str, Any] = Field(default_factory=dict)
    scene_hash: str | None = None
    build_inputs_hash: str | None = None
    rt: dict[str, Any] = Field(default_factory=dict)
    transmitter: dict[str, Any] = Field(default_factory=dict)
    transmitters: list[dict[str, Any]] | None = None
    """Every transmitter, transmitter 0 first: written only for a twin with several."""
    grid: dict[str, Any] = Field(default_factory=dict)
    rx_height_m: float | list[float] | None = None
    robot_height_m: float | None = None
    library_versions: dict[str, str] = Field(default_factory=dict)
    stats: dict[str, Any] = Field(default_factory=dict)
    files: dict[str, FileRecord] = Field(default_factory=dict)

    @classmethod
    def from_meta(cls, meta: dict[str, Any], *, where: str = "meta.json") -> VersionRecord:
        """The record of a ``meta.json`` object of any format this package knows."""
        if not isinstance(meta, dict):
            raise CorruptDatasetError(
                f"{where} holds {type(meta).__name__}, not a version record",
                hint="rebuild the dataset (`make dataset`) or pull it again",
            )
        fmt = meta.get("record_format", 0)
        if not isinstance(fmt, int) or fmt > RECORD_FORMAT:
            raise CorruptDatasetError(
                f"{where} is version record format {fmt!r}; this dtradar reads formats 0..{RECORD_FORMAT}",
                hint="upgrade dtradar (`pip install -U dtradar`)",
            )
        data = dict(meta)
        if fmt == 0:
            spec = data.get("scene_spec") or {}
            for key, spec_key in _FROM_SPEC:
                if data.get(key) in (None, "", {}) and spec.get(spec_key) not in (None, ""):
                    data[key] = spec[spec_key]
            data["record_format"] = RECORD_FORMAT
        try:
            return cls.model_validate(data)
        except ValidationError as e:
            first = e.errors()[0]
            field = ".".join(str(p) for p in first["loc"]) or "(record)"
            raise CorruptDatasetError(
                f"{where}: field {field!r}: {first['msg']}",
                hint="rebuild the dataset (`make dataset`) or pull it again",
            ) from e

    def to_meta(self) -> dict[str, Any]:
        """The JSON object written to ``meta.json``."""
        return self.model_dump(mode="json")

    @property
    def num_rows(self) -> int:
        if "num_cells" in self.stats:
            return int(self.stats["num_cells"])
        return int(self.grid.get("nx", 0)) * int(self.grid.get("ny", 0))
