"""Logged datasets: transitions of a behaviour policy on a twin, stored, versioned and carded like the RT datasets.

An offline-RL dataset is a *transition table* logged on one RT dataset (its *parent*) by one behaviour policy. This
package is its storage half (numpy and pyarrow only: the behaviour policies and rollouts live in
:mod:`dtradar_rl.offline.logged`, which needs torch). Import everything from here (``from dtradar_data.store.logged
import load_logged``); the modules mirror :mod:`dtradar_data.store`:

- names: ``<scene>/<variant>/<behaviour>[@<revision>]``, e.g. ``cubicle/blueprint/noisy-shortest`` or
  ``cubicle/blueprint/mixture@v0``, the second form of the dataset-id grammar in :mod:`dtradar_data.core.ids`
  (:class:`LoggedId`, :func:`parse_logged_id`, :func:`format_logged_id`, :func:`is_logged_name`);
- :mod:`.table` — the transition table: schema, invariants (:func:`check_transitions`), numpy views, episode stats;
- :mod:`.versions` — a version is the hash of the logging inputs (:func:`logging_inputs`, :func:`logged_version`);
- :mod:`.dataset` — :class:`LoggedDataset`, one loaded version, its Minari id and Minari folder (:func:`minari_root`:
  ``$MINARI_DATASETS_PATH``, else ``<root>/minari``, one per data root);
- :mod:`.card` — the dataset card of a version, a pure function of its metadata;
- :mod:`.local` — the layout under ``<root>/logged``, atomic writes, installs of a download, checked reads
  (:func:`write_logged`, :func:`load_logged`);
- :mod:`.listing` — every stored logged version, damaged ones flagged (:func:`list_logged`), and full verification
  (:func:`verify_logged`);
- :mod:`.staging` — staging folders held by their process (those of killed ones are cleaned), locks that say what
  they wait for;
- :mod:`.hints` — the ``python -m dtradar_rl log`` / ``make log`` command that (re)creates a version.
"""

from dtradar_data.core.ids import LOGGED_GRAMMAR, LoggedId, format_logged_id, is_logged_name, parse_logged_id
from dtradar_data.store.logged.card import render_logged_card
from dtradar_data.store.logged.dataset import MINARI_DIR, MINARI_ENV, LoggedDataset, minari_id, minari_root
from dtradar_data.store.logged.hints import log_commands, relog_hint
from dtradar_data.store.logged.listing import LoggedEntry, list_logged, verify_logged, verify_logged_dir
from dtradar_data.store.logged.local import (
    LOGGED_DIR,
    META_KEY,
    STAGE_PREFIXES,
    check_version_dir,
    clean_logged_stages,
    install_logged,
    load_logged,
    local_versions,
    logged_dir,
    logged_names,
    logged_root,
    logging_lock,
    looks_like_stage,
    read_meta,
    read_transitions,
    refs_path,
    resolve_logged,
    write_logged,
)
from dtradar_data.store.logged.table import (
    COLUMN_DESCRIPTIONS,
    TRANSITION_SCHEMA,
    TRANSITIONS_FILE,
    TRANSITIONS_FORMAT,
    arrays,
    check_transitions,
    episode_stats,
    transitions_table,
)
from dtradar_data.store.logged.versions import LOGGED_LIBRARIES, logged_version, logging_inputs, table_digest

__all__ = [
    "COLUMN_DESCRIPTIONS",
    "LOGGED_DIR",
    "LOGGED_GRAMMAR",
    "LOGGED_LIBRARIES",
    "META_KEY",
    "MINARI_DIR",
    "MINARI_ENV",
    "STAGE_PREFIXES",
    "TRANSITIONS_FILE",
    "TRANSITIONS_FORMAT",
    "TRANSITION_SCHEMA",
    "LoggedDataset",
    "LoggedEntry",
    "LoggedId",
    "arrays",
    "check_transitions",
    "check_version_dir",
    "clean_logged_stages",
    "episode_stats",
    "format_logged_id",
    "install_logged",
    "is_logged_name",
    "list_logged",
    "load_logged",
    "local_versions",
    "log_commands",
    "logged_dir",
    "logged_names",
    "logged_root",
    "logged_version",
    "logging_inputs",
    "logging_lock",
    "looks_like_stage",
    "minari_id",
    "minari_root",
    "parse_logged_id",
    "read_meta",
    "read_transitions",
    "refs_path",
    "relog_hint",
    "render_logged_card",
    "resolve_logged",
    "table_digest",
    "transitions_table",
    "verify_logged",
    "verify_logged_dir",
    "write_logged",
]
