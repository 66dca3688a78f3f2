"""Versions of a logged dataset: the 16-hex sha256 prefix of the canonical JSON of its *logging inputs*.

The inputs: the parent's name and content version, the behaviour policy with all its parameters (a checkpoint by its
sha256), the number of steps, the seed, the number of parallel robots, the observation preset, the reward, the step
limit, the table's format and the library versions (numpy, pyarrow, torch: the rollouts draw from torch's
generators). The same name and settings give the same version (logging again reuses it); any change gives a new one,
tagged ``v0``, ``v1``, ... in ``refs.json`` exactly as for RT datasets (:mod:`dtradar_data.store.versions`).
"""

from __future__ import annotations

import hashlib
from typing import Any

import pyarrow as pa

from dtradar_data.store.logged.table import TRANSITIONS_FORMAT
from dtradar_data.store.versions import library_versions, version_id

__all__ = ["LOGGED_LIBRARIES", "logging_inputs", "logged_version", "table_digest"]

#: Libraries whose versions change logged content: numpy/pyarrow (files), torch (the rollouts' random streams).
LOGGED_LIBRARIES: tuple[str, ...] = ("dtradar", "numpy", "pyarrow", "torch")


def logging_inputs(
    *,
    parent: str,
    parent_version: str,
    behaviour: dict[str, Any],
    steps: int,
    seed: int,
    settings: dict[str, Any],
    libraries: dict[str, str] | None = None,
) -> dict[str, Any]:
    """What a logged version hashes: parent (name and content version), behaviour and all its parameters, steps,
    seed, the environment settings (robots, observation preset, reward, step limit), format and libraries."""
    return {
        "parent": parent,
        "parent_version": parent_version,
        "behaviour": behaviour,
        "steps": int(steps),
        "seed": int(seed),
        "settings": settings,
        "format": TRANSITIONS_FORMAT,
        "library_versions": library_versions(LOGGED_LIBRARIES) if libraries is None else dict(libraries),
    }


def logged_version(inputs: dict[str, Any]) -> str:
    return version_id(inputs)


def table_digest(table: pa.Table) -> str:
    """A content hash of an in-memory table (for parents without a stored version, e.g. synthetic twins)."""
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema.remove_metadata()) as w:
        w.write_table(table.replace_schema_metadata(None))
    return "sha256:" + hashlib.sha256(sink.getvalue().to_pybytes()).hexdigest()[:16]
