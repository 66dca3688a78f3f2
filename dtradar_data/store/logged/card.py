"""The Hugging Face dataset card (``README.md``) of a logged version: a pure function of its metadata and tag."""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

from dtradar_data.core.files import human_size
from dtradar_data.core.ids import parse_logged_id
from dtradar_data.store.logged.dataset import minari_id
from dtradar_data.store.logged.table import (
    COLUMN_DESCRIPTIONS,
    TRANSITION_SCHEMA,
    TRANSITIONS_FILE,
    TRANSITIONS_FORMAT,
)

__all__ = ["render_logged_card"]


def render_logged_card(meta: dict[str, Any], tag: str | None) -> str:
    """The Hugging Face dataset card (``README.md``) of a logged version: a pure function of its meta and tag."""
    from huggingface_hub import DatasetCard, DatasetCardData

    lid = parse_logged_id(meta["name"])
    stats = meta.get("stats") or {}
    data = DatasetCardData(
        license="apache-2.0",
        pretty_name=f"dtradar logged transitions {lid.name}",
        tags=["robotics", "reinforcement-learning", "offline-rl", "wireless", "digital-twin", "parquet", "minari"],
        task_categories=["reinforcement-learning"],
        configs=[{"config_name": "transitions", "data_files": TRANSITIONS_FILE, "default": True}],
        dtradar={
            "name": lid.name,
            "version": meta["version"],
            "tag": tag,
            "parent": meta["parent"],
            "parent_version": meta["parent_version"],
            "format": TRANSITIONS_FORMAT,
        },
    )
    template = resources.files("dtradar_data.store").joinpath("templates/logged_card.md").read_text()
    files = meta.get("files") or {}
    beh = meta.get("behaviour") or {}
    card = DatasetCard.from_template(
        data,
        template_str=template,
        name=lid.name,
        version=meta["version"],
        tag=tag,
        created_utc=meta.get("created_utc"),
        parent=meta["parent"],
        parent_version=meta["parent_version"],
        behaviour=beh,
        behaviour_json=json.dumps(beh, sort_keys=True),
        behaviour_text=meta.get("behaviour_text", ""),
        family=meta.get("family"),
        score=meta.get("score") or {},
        medium_agent=meta.get("medium_agent") or {},
        moving=meta.get("moving") or {},
        steps=meta.get("steps"),
        seed=meta.get("seed"),
        settings=meta.get("settings") or {},
        stats=stats,
        obs=meta.get("observations") or {},
        normalizer=json.dumps(meta.get("normalizer") or {}),
        minari=minari_id(lid, tag),
        columns=[(f.name, str(f.type), COLUMN_DESCRIPTIONS[f.name]) for f in TRANSITION_SCHEMA],
        size=human_size((files.get(TRANSITIONS_FILE) or {}).get("bytes")),
        libraries=meta.get("library_versions") or {},
        version_hash_inputs=", ".join(sorted((meta.get("inputs") or {}).keys())),
    )
    return str(card)
