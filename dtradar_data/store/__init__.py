"""The local dataset store: versioned, content-hashed Parquet under the data root.

- :mod:`.versions` — version ids (content hashes of the build inputs) and the tags in ``refs.json``;
- :mod:`.local` — checked reads of a stored version, ``load``;
- :mod:`.writing` — atomic writes of one version and installs of a download;
- :mod:`.staging` — staging folders held by their process; those a killed writer or pull left are removed;
- :mod:`.listing` — every dataset and version, full verification, history;
- :mod:`.writers` — which versions a live process is writing right now (for ``verify``: unfinished, not damaged);
- :mod:`.catalog` — which dataset names exist (built-in scenes and stored ones);
- :mod:`.card` — the dataset card of a version, a pure function of its metadata;
- :mod:`.logged` — logged (offline-RL) datasets: transition tables stored, versioned and carded the same way.
"""

from dtradar_data.store.catalog import as_id, known_names, known_scenes
from dtradar_data.store.listing import (
    DatasetEntry,
    VersionInfo,
    history,
    list_datasets,
    verify,
    version_infos,
)
from dtradar_data.store.local import (
    load,
    read_meta,
    read_table,
    resolve,
    version_exists,
)
from dtradar_data.store.staging import clean_stale_stages, held_stage
from dtradar_data.store.versions import library_versions, read_refs, version_id
from dtradar_data.store.writing import InvalidTableError, install_staged, write_version

__all__ = [
    "as_id",
    "clean_stale_stages",
    "DatasetEntry",
    "held_stage",
    "history",
    "install_staged",
    "InvalidTableError",
    "known_names",
    "known_scenes",
    "library_versions",
    "list_datasets",
    "load",
    "read_meta",
    "read_refs",
    "read_table",
    "resolve",
    "verify",
    "version_exists",
    "version_id",
    "version_infos",
    "VersionInfo",
    "write_version",
]
