"""Dataset cards: a Hugging Face ``README.md`` (YAML front matter + prose) rendered from a version's ``meta.json``.

Rendering uses ``huggingface_hub.DatasetCard.from_template`` with ``dtradar_data/templates/dataset_card.md``; the
front matter (``DatasetCardData``) carries licence, tags, size category and ``configs`` whose ``data_files`` point at
``cells.parquet`` / ``paths.parquet`` in the same directory, so the Hub viewer and ``datasets.load_dataset`` read
the Parquet directly. A card is a pure function of ``(meta, tag, history, hub_repo)``: no clock, no environment.
The store writes the card of every version it installs; :mod:`dtradar_data.publish.cards` keeps the committed copies.
"""

from __future__ import annotations

from collections import Counter
from importlib import resources
from typing import Any

from huggingface_hub import DatasetCard, DatasetCardData

from dtradar_data.core import layout as P
from dtradar_data.core.files import human_size
from dtradar_data.core.record import VersionRecord
from dtradar_data.core.schema import (
    CELL_SCHEMA,
    COLUMN_DESCRIPTIONS,
    MOVING_CELL_SCHEMA,
    MOVING_COLUMN_DESCRIPTIONS,
    MOVING_PATH_COLUMN_DESCRIPTIONS,
    MOVING_PATH_SCHEMA,
    PATH_COLUMN_DESCRIPTIONS,
    PATH_SCHEMA,
    cell_schema,
    path_schema,
)
from dtradar_data.store.card_sections import city_section as _city_section
from dtradar_data.store.card_sections import fmt as _fmt
from dtradar_data.store.card_sections import moving_section as _moving_section
from dtradar_data.store.card_sections import tx_pose_section as _tx_pose_section

DEFAULT_HUB_NAMESPACE = "dtradar"
TAGS = ("robotics", "reinforcement-learning", "wireless", "radio", "ray-tracing", "sionna", "digital-twin", "parquet")
VARIANT_TEXT = {
    "blueprint": "the static twin: walls, floor and the fixed furniture or buildings (agents are trained here).",
    "dynamic": "the blueprint plus movable objects added or re-oriented (people, chairs, vehicles); agents trained "
    "on the blueprint are evaluated here.",
    "moving": "people or vehicles moving through the twin, one snapshot of the world per robot step: the table holds "
    "every snapshot (column `t`), a cell a mover covers is blocked then (column `mover`).",
}
#: The animation a moving twin's version carries (written by :mod:`dtradar_data.pipeline.moving`).
MOVING_GIF_FILE = P.MOVING_GIF_FILE
#: A moving twin's card lists at most this many snapshots one by one (the first ones, then a summary).
_UNITS = (("_rad", "rad"), ("_db", "dB"), ("_hz", "Hz"), ("_m", "m"), ("_s", "s"))
# Hub licence identifiers (https://huggingface.co/docs/hub/repositories-licenses) for the licences scenes use.
_LICENCES = {
    "odbl": "odbl",
    "odbl-1.0": "odbl",
    "cc-by-4.0": "cc-by-4.0",
    "cc-by-sa-4.0": "cc-by-sa-4.0",
    "cc0-1.0": "cc0-1.0",
    "cc0": "cc0-1.0",
    "apache-2.0": "apache-2.0",
    "mit": "mit",
    "cc-by-nc-4.0": "cc-by-nc-4.0",
    "pddl": "pddl",
    "odc-by": "odc-by",
}


def default_hub_repo(name: str) -> str:
    """``dtradar/dtradar-<scene>-<variant>``: the repo the cards advertise (``publish --repo`` overrides it)."""
    scene, variant = name.split("/")
    return f"{DEFAULT_HUB_NAMESPACE}/dtradar-{scene}-{variant}"


def license_id(licence: str | None) -> str:
    text = (licence or "").strip().lower()
    if text in _LICENCES:
        return _LICENCES[text]
    if "odbl" in text or "open database" in text:
        return "odbl"
    return "other"


def size_category(n: int) -> str:
    for limit, label in (
        (1_000, "n<1K"),
        (10_000, "1K<n<10K"),
        (100_000, "10K<n<100K"),
        (1_000_000, "100K<n<1M"),
        (10_000_000, "1M<n<10M"),
    ):
        if n < limit:
            return label
    return "10M<n<100M"


def _unit(column: str) -> str:
    if column.endswith("_rad"):
        return "rad"
    return next((u for suffix, u in _UNITS if column.endswith(suffix)), "—")


def _flatten(d: dict[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for k, v in sorted(d.items()):
        if isinstance(v, dict) and v:
            out += _flatten(v, f"{prefix}{k}.")
        else:
            out.append((f"{prefix}{k}", v))
    return out


def history_entry(tag: str, meta: dict[str, Any]) -> dict[str, Any]:
    """The part of a version's meta the history table needs (kept small in ``card.json``)."""
    keys = ("version", "created_utc", "schema_version", "scene_hash", "rt", "library_versions")
    return {"tag": tag, **{k: meta.get(k) for k in keys}}


def _changes(prev: dict[str, Any] | None, cur: dict[str, Any]) -> str:
    if prev is None:
        return "first version"
    out = []
    if prev.get("schema_version") != cur.get("schema_version"):
        out.append(f"schema v{prev.get('schema_version')} → v{cur.get('schema_version')}")
    if prev.get("scene_hash") != cur.get("scene_hash"):
        out.append("scene description changed")
    a, b = dict(_flatten(prev.get("rt") or {})), dict(_flatten(cur.get("rt") or {}))
    out += [f"`{k}` {_fmt(a.get(k))} → {_fmt(b.get(k))}" for k in sorted(a.keys() | b.keys()) if a.get(k) != b.get(k)]
    la, lb = prev.get("library_versions") or {}, cur.get("library_versions") or {}
    out += [f"{k} {la.get(k, '—')} → {lb.get(k, '—')}" for k in sorted(la.keys() | lb.keys()) if la.get(k) != lb.get(k)]
    return "; ".join(out) or "rebuilt with the same inputs"


def _field_descriptions(schema) -> dict[str, str]:
    return {f.name: (f.metadata or {}).get(b"description", b"").decode() for f in schema}


def _transmitter_table(rec: VersionRecord) -> list[dict[str, Any]]:
    """One row per transmitter of a twin with several: its index, name, column prefix, position and pose."""
    rows = []
    for k, t in enumerate(rec.transmitters or []):
        rows.append(
            {
                "k": k,
                "name": t.get("name") or f"tx{k}",
                "prefix": "(none)" if k == 0 else f"`tx{k}_`",
                "position": _fmt(t.get("position_m")),
                "look_at": _fmt(t.get("look_at_m") or t.get("orientation_deg")),
                "reached": (rec.stats.get("num_with_paths_per_tx") or ["—"] * (k + 1))[k],
            }
        )
    return rows


def _columns(schema, descriptions) -> list[dict[str, Any]]:
    return [
        {
            "name": f.name,
            "type": str(f.type),
            "nullable": f.nullable,
            "unit": _unit(f.name),
            "description": descriptions.get(f.name, "").replace("|", "\\|"),
        }
        for f in schema
    ]


def card_data(rec: VersionRecord, *, tag: str | None, hub_repo: str) -> DatasetCardData:
    configs = [{"config_name": "cells", "data_files": [{"split": "train", "path": P.CELLS_FILE}], "default": True}]
    if P.PATHS_FILE in rec.files:
        configs.append({"config_name": "paths", "data_files": [{"split": "train", "path": P.PATHS_FILE}]})
    setting = "outdoor" if "outdoor" in str(rec.scene_spec.get("kind", "")) or _is_odbl(rec) else "indoor"
    lic = license_id(rec.licence)
    extra: dict[str, Any] = {}
    if lic == "other":
        extra["license_name"] = rec.licence or "unspecified"
    return DatasetCardData(
        license=lic,
        pretty_name=_pretty_name(rec),
        tags=[*TAGS, setting, rec.variant],
        size_categories=[size_category(rec.num_rows)],
        task_categories=["robotics", "reinforcement-learning"],
        configs=configs,
        dtradar={
            "name": rec.name,
            "version": rec.version,
            "tag": tag,
            "schema_version": rec.schema_version,
            "hub_repo": hub_repo,
        },
        **extra,
    )


def _is_odbl(rec: VersionRecord) -> bool:
    return license_id(rec.licence) == "odbl"


def _pretty_name(rec: VersionRecord) -> str:
    title = rec.title or rec.scene
    return f"DT-RaDaR {title}" if rec.variant in title.lower() else f"DT-RaDaR {title} ({rec.variant})"


def render_card(
    meta: dict[str, Any], *, tag: str | None, history: list[dict[str, Any]], hub_repo: str | None = None
) -> str:
    """The card text for one version. ``history`` holds :func:`history_entry` dicts, oldest first."""
    rec = VersionRecord.from_meta(meta)
    hub_repo = hub_repo or default_hub_repo(rec.name)
    moving = _moving_section(rec)
    card = DatasetCard.from_template(
        card_data(rec, tag=tag, hub_repo=hub_repo),
        template_path=str(resources.files("dtradar_data.store") / "templates" / "dataset_card.md"),
        summary=_summary(rec, moving),
        moving=moving,
        hub_repo=hub_repo,
        history=_history_rows(history),
        **_version_values(rec, tag),
        **_scene_values(rec),
        **_tracing_values(rec),
        **_table_values(rec, moving),
    )
    return str(card).rstrip("\n") + "\n"


def _summary(rec: VersionRecord, moving: dict[str, Any] | None) -> str:
    """The card's opening paragraph: what the table holds, over which twin, traced how."""
    grid, freq = rec.grid, rec.rt.get("frequency_hz")
    over_time = f", in {moving['snapshots']} snapshots {moving['dt_s']} s apart," if moving else ","
    return (
        f"Radio features of every cell of a {grid.get('nx')} × {grid.get('ny')} grid over the "
        f"**{rec.title or rec.scene}** digital twin ({rec.variant}){over_time} ray-traced with Sionna RT"
        + (f" at {freq / 1e9:g} GHz" if isinstance(freq, (int, float)) else "")
        + ": complex coefficient, phase, delay and angles of departure and arrival of the strongest path, "
        "total path gain and delay spread. Built for radio-only robot navigation with reinforcement "
        "learning, after DT-RaDaR (arXiv 2411.12284)."
    )


def _history_rows(history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The history table: each entry with its date (or a dash) and what changed since the one before."""
    return [
        {**h, "created_utc": h.get("created_utc") or "—", "changes": _changes(history[i - 1] if i else None, h)}
        for i, h in enumerate(history)
    ]


def _version_values(rec: VersionRecord, tag: str | None) -> dict[str, Any]:
    """The template's values naming the version: name, tag, schema, date, its files and pictures."""
    return {
        "pretty_name": _pretty_name(rec),
        "name": rec.name,
        "version": rec.version,
        "tag": tag,
        "schema_version": rec.schema_version,
        "created_utc": rec.created_utc or "—",
        "files": [
            {"name": k, "size": human_size(f.bytes), "sha256": f.sha256[:16]} for k, f in sorted(rec.files.items())
        ],
        "coverage": P.COVERAGE_FILE if P.COVERAGE_FILE in rec.files else None,
        "cells_png": P.CELLS_PICTURE_FILE if P.CELLS_PICTURE_FILE in rec.files else None,
        "city_png": CITY_FILE if CITY_FILE in rec.files else None,
        "scene_xml": P.SCENE_XML if P.SCENE_XML in rec.files else None,
    }


_POSE_KEYS = ("name", "position_m", "look_at_m", "orientation_deg")


def _scene_values(rec: VersionRecord) -> dict[str, Any]:
    """The template's values describing the twin: grid, heights, variant, transmitter, objects and provenance."""
    grid = rec.grid
    objects = [*(rec.scene_spec.get("objects") or []), *(rec.scene_spec.get("prisms") or [])]
    counts = Counter((o.get("kind", "?"), o.get("material", "?")) for o in objects)
    return {
        "nx": grid.get("nx"),
        "ny": grid.get("ny"),
        "cell_m": grid.get("cell_m"),
        "x0_m": grid.get("x0_m"),
        "y0_m": grid.get("y0_m"),
        "rx_height_m": _fmt(rec.rx_height_m),
        "robot_height_m": rec.robot_height_m,
        "description": rec.description or "(no scene description recorded)",
        "variant": rec.variant,
        "variant_text": VARIANT_TEXT.get(rec.variant, ""),
        "transmitter_rows": [] if rec.transmitters else [(k, _fmt(v)) for k, v in _flatten(rec.transmitter)],
        "transmitters": _transmitter_table(rec),
        "array_rows": [(k, _fmt(v)) for k, v in _flatten(rec.transmitter) if k not in _POSE_KEYS],
        "object_rows": [(k, m, c) for (k, m), c in sorted(counts.items())],
        "num_objects": len(objects),
        "source": rec.source or "not recorded",
        "licence": rec.licence or "not recorded",
        "attribution": rec.attribution or "not recorded",
        "odbl": _is_odbl(rec),
        "city": _city_section(rec),
        "differential": (rec.model_extra or {}).get("differential"),
        "tx_pose": _tx_pose_section(rec),
    }


def _tracing_values(rec: VersionRecord) -> dict[str, Any]:
    """The template's values on how the twin was traced: Sionna's version, the RT settings, the libraries."""
    libs = rec.library_versions
    return {
        "sionna_version": f"sionna-rt {libs['sionna-rt']}" if "sionna-rt" in libs else "version not recorded",
        "rt_rows": [(k, _fmt(v)) for k, v in _flatten(rec.rt)] or [("(none recorded)", "—")],
        "library_text": ", ".join(f"{k} {v}" for k, v in sorted(libs.items())) or "not recorded",
    }


def _table_values(rec: VersionRecord, moving: dict[str, Any] | None) -> dict[str, Any]:
    """The template's values on the tables: their columns, row counts and each column's range."""
    n, stats = rec.num_rows, rec.stats
    cells = (MOVING_CELL_SCHEMA, MOVING_COLUMN_DESCRIPTIONS) if moving else (CELL_SCHEMA, COLUMN_DESCRIPTIONS)
    paths = (MOVING_PATH_SCHEMA, MOVING_PATH_COLUMN_DESCRIPTIONS) if moving else (PATH_SCHEMA, PATH_COLUMN_DESCRIPTIONS)
    k = len(rec.transmitters or []) or 1  # several transmitters: their schemas, descriptions from the fields
    channels = bool((rec.rt or {}).get("path_channels"))  # --rt.path-channels: the channel columns too
    if k > 1 or channels:
        cells = (cell_schema(False, k), _field_descriptions(cell_schema(False, k))) if k > 1 else cells
        paths = (path_schema(False, k, channels), _field_descriptions(path_schema(False, k, channels)))
    ranges = stats.get("columns") or {}
    return {
        "num_rows": n,
        "columns": _columns(*cells),
        "path_columns": _columns(*paths) if P.PATHS_FILE in rec.files else [],
        "num_free": stats.get("num_free", "—"),
        "num_with_paths": stats.get("num_with_paths", "—"),
        "num_blocked": (n - stats["num_free"]) if "num_free" in stats else "—",
        "range_rows": [
            {"name": c, "min": _fmt(r.get("min")), "max": _fmt(r.get("max")), "nulls": r.get("nulls", "—")}
            for c, r in ranges.items()
            if isinstance(r, dict)
        ],
    }


CITY_FILE = P.CITY_FILE


def render_version_card(
    meta: dict[str, Any], *, tag: str | None, history: list[tuple[str, dict[str, Any]]], hub_repo: str | None = None
) -> str:
    """The card of a stored version; ``history`` holds ``(tag, meta)`` pairs, oldest first (store's format)."""
    return render_card(meta, tag=tag, history=[history_entry(t, m) for t, m in history], hub_repo=hub_repo)
