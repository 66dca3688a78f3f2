"""Logged datasets: transitions of a behaviour policy on a twin, stored, versioned and carded like the RT datasets.

An offline-RL dataset is a *transition table* logged on one RT dataset (its *parent*) by one behaviour policy. This
module is its storage half (numpy and pyarrow only: the behaviour policies and rollouts live in
:mod:`dtradar_rl.logged`, which needs torch).

Names
-----
``<scene>/<variant>/<behaviour>[@<revision>]``, e.g. ``cubicle/blueprint/noisy-shortest`` or
``cubicle/blueprint/mixture@v0``: the parent ``scene/variant`` (the twin the transitions were logged on), then the
behaviour's name (``[a-z0-9][a-z0-9_-]*``; by default the behaviour policy's kind), then, as for RT datasets, an
optional tag or content-hash prefix. Two slashes tell a logged dataset from an RT dataset (one slash), so
:func:`dtradar_data.load` accepts both. :func:`parse_logged_id` and :func:`format_logged_id` are inverse.

Versions
--------
The 16-hex sha256 prefix of the canonical JSON of the *logging inputs*: the parent's name and content version, the
behaviour policy with all its parameters (a checkpoint by its sha256), the number of steps, the seed, the number of
parallel robots, the observation preset, the reward, the step limit, this table's format and the library versions
(numpy, pyarrow, torch: the rollouts draw from torch's generators). The same name and settings give the same version
(logging again reuses it); any change gives a new one, tagged ``v0``, ``v1``, ... in ``refs.json`` exactly as for RT
datasets (:mod:`dtradar_data.store.versions`).

Layout
------
``<root>/logged/<scene>/<variant>/<behaviour>/<version>/{transitions.parquet, meta.json, README.md}`` and
``.../<behaviour>/refs.json``: a tree apart from ``<root>/datasets`` so that RT listings never see them. A version is
written into a staging folder under ``<root>/work`` and renamed into place (complete or absent).

The table (:data:`TRANSITION_SCHEMA`, one row per environment step, episodes contiguous and in order)
--------------------------------------------------------------------------------------------------------
``episode, step, obs, action, reward, next_obs, terminated, truncated, robot, cell, target, component``.
``obs`` is the observation the action was chosen from, ``next_obs`` the one after the move; within an episode
``next_obs[t] == obs[t + 1]``. The last step of every episode has exactly one flag: ``terminated`` (the target was
reached: a true terminal, bootstrap with 0) or ``truncated`` (cut by the step limit or by the end of logging: not a
terminal, bootstrap from ``next_obs``); no other step has either. :func:`check_transitions` enforces all of it.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from filelock import FileLock

from dtradar_data.core import layout as P
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DatasetNotFoundError,
    SchemaMismatchError,
    UnknownNameError,
)
from dtradar_data.core.files import human_size, json_safe, sha256_file, write_atomic
from dtradar_data.core.ids import GRAMMAR as RT_GRAMMAR
from dtradar_data.core.ids import HASH_RE, SCENE_RE, VARIANTS, is_hash, is_tag
from dtradar_data.store.versions import (
    Refs,
    library_versions,
    read_refs,
    resolve_revision,
    version_id,
    write_refs,
)

TRANSITIONS_FORMAT = 1
TRANSITIONS_FILE = "transitions.parquet"
LOGGED_DIR = "logged"
META_KEY = b"dtradar.logged"
#: Libraries whose versions change logged content: numpy/pyarrow (files), torch (the rollouts' random streams).
LOGGED_LIBRARIES: tuple[str, ...] = ("dtradar", "numpy", "pyarrow", "torch")
GRAMMAR = "<scene>/<variant>/<behaviour>[@<revision>], e.g. 'cubicle/blueprint/noisy-shortest'"

TRANSITION_SCHEMA = pa.schema([
    pa.field("episode", pa.int64(), nullable=False, metadata={"description": "episode number, 0.. in file order"}),
    pa.field("step", pa.int32(), nullable=False, metadata={"description": "step within the episode, 0.."}),
    pa.field("obs", pa.list_(pa.float32()), nullable=False,
             metadata={"description": "normalised observation the action was chosen from"}),
    pa.field("action", pa.int8(), nullable=False, metadata={"description": "0 X-, 1 X+, 2 Y-, 3 Y+"}),
    pa.field("reward", pa.float32(), nullable=False, metadata={"description": "reward of the move"}),
    pa.field("next_obs", pa.list_(pa.float32()), nullable=False,
             metadata={"description": "observation after the move (the next row's obs within an episode)"}),
    pa.field("terminated", pa.bool_(), nullable=False,
             metadata={"description": "the move reached the target: the episode ends in a true terminal"}),
    pa.field("truncated", pa.bool_(), nullable=False,
             metadata={"description": "the episode was cut here (step limit or end of logging), not a terminal"}),
    pa.field("robot", pa.int32(), nullable=False, metadata={"description": "which parallel robot logged the step"}),
    pa.field("cell", pa.int32(), nullable=False, metadata={"description": "row-major cell index before the move"}),
    pa.field("target", pa.int32(), nullable=False, metadata={"description": "the episode's target cell index"}),
    pa.field("component", pa.int8(), nullable=False,
             metadata={"description": "mixture component that acted (index into meta behaviour.components; 0 "
                                      "for a single policy)"}),
])
COLUMN_DESCRIPTIONS = {f.name: f.metadata[b"description"].decode() for f in TRANSITION_SCHEMA}


# ----------------------------------------------------------------------------------------------------------- names

@dataclass(frozen=True)
class LoggedId:
    """A parsed logged-dataset id; ``revision`` None means the newest version."""

    scene: str
    variant: str
    behaviour: str
    revision: str | None = None

    @property
    def name(self) -> str:
        return f"{self.scene}/{self.variant}/{self.behaviour}"

    @property
    def parent(self) -> str:
        """The RT dataset the transitions were logged on."""
        return f"{self.scene}/{self.variant}"

    def with_revision(self, revision: str | None) -> LoggedId:
        return LoggedId(self.scene, self.variant, self.behaviour, revision)

    def __str__(self) -> str:
        return format_logged_id(self)


def is_logged_name(text: Any) -> bool:
    """Whether ``text`` has the shape of a logged-dataset id (three ``/``-separated parts before any ``@``)."""
    return isinstance(text, (str, LoggedId)) and (isinstance(text, LoggedId) or text.partition("@")[0].count("/") == 2)


def parse_logged_id(text: str | LoggedId) -> LoggedId:
    """Parse ``scene/variant/behaviour[@revision]``; :class:`UnknownNameError` with the grammar otherwise."""
    if isinstance(text, LoggedId):
        return text
    if not isinstance(text, str):
        raise UnknownNameError(f"logged dataset id must be a string, got {type(text).__name__}", hint=f"use {GRAMMAR}")
    name, sep, revision = text.strip().partition("@")
    if sep and not (is_tag(revision) or (is_hash(revision) and len(revision) >= 7)):
        raise UnknownNameError(f"revision {revision!r} in {text!r} is neither a tag nor a version hash",
                               hint="use a tag like 'v0' or at least 7 lowercase hex characters of a version hash")
    parts = name.split("/")
    if len(parts) != 3 or not all(SCENE_RE.fullmatch(p) for p in parts):
        raise UnknownNameError(f"malformed logged dataset id {text!r}",
                               hint=f"use {GRAMMAR} (an RT dataset is {RT_GRAMMAR})")
    scene, variant, behaviour = parts
    if variant not in VARIANTS:
        raise UnknownNameError(f"unknown variant {variant!r} in {text!r}", hint=f"use one of: {', '.join(VARIANTS)}")
    return LoggedId(scene, variant, behaviour, revision or None)


def format_logged_id(lid: LoggedId) -> str:
    """The inverse of :func:`parse_logged_id`."""
    return lid.name + (f"@{lid.revision}" if lid.revision else "")


def minari_id(lid: LoggedId, tag: str | None) -> str:
    """The Minari id of a logged version: ``dtradar/<scene>-<variant>-<behaviour>-v<N>`` (``N`` from tag ``vN``)."""
    n = int(tag[1:]) if tag and is_tag(tag) else 0
    return f"dtradar/{lid.scene}-{lid.variant}-{lid.behaviour}-v{n}"


# ---------------------------------------------------------------------------------------------------------- layout

def logged_root() -> Path:
    return P.data_root() / LOGGED_DIR


def logged_dir(lid: LoggedId) -> Path:
    return logged_root() / lid.scene / lid.variant / lid.behaviour


def _refs_path(lid: LoggedId) -> Path:
    return logged_dir(lid) / P.REFS_FILE


def local_versions(lid: LoggedId) -> list[str]:
    """Version folders of ``lid`` (complete ones: with meta.json), oldest tag first."""
    d = logged_dir(lid)
    if not d.is_dir():
        return []
    found = [p.name for p in d.iterdir() if p.is_dir() and HASH_RE.fullmatch(p.name) and (p / P.META_FILE).is_file()]
    order = {v: i for i, (_, v) in enumerate(read_refs(_refs_path(lid)).ordered())}
    return sorted(found, key=lambda v: (order.get(v, len(order)), v))


# ---------------------------------------------------------------------------------------------------------- tables

def transitions_table(*, episode, step, obs, action, reward, next_obs, terminated, truncated, robot, cell, target,
                      component=None) -> pa.Table:
    """The transition table from numpy arrays (``obs``/``next_obs``: float32[T, D]), checked by
    :func:`check_transitions`."""
    obs = np.ascontiguousarray(obs, np.float32)
    next_obs = np.ascontiguousarray(next_obs, np.float32)
    n = len(obs)
    if obs.ndim != 2 or next_obs.shape != obs.shape:
        raise SchemaMismatchError(f"obs {obs.shape} and next_obs {next_obs.shape} must both be [T, D]",
                                  hint="pass one observation row per step")

    def lists(x: np.ndarray) -> pa.Array:
        offsets = pa.array(np.arange(0, n * x.shape[1] + 1, x.shape[1], dtype=np.int32))
        return pa.ListArray.from_arrays(offsets, pa.array(x.reshape(-1)))

    comp = np.zeros(n, np.int8) if component is None else np.asarray(component, np.int8)
    cols = [np.asarray(episode, np.int64), np.asarray(step, np.int32), lists(obs), np.asarray(action, np.int8),
            np.asarray(reward, np.float32), lists(next_obs), np.asarray(terminated, bool),
            np.asarray(truncated, bool), np.asarray(robot, np.int32), np.asarray(cell, np.int32),
            np.asarray(target, np.int32), comp]
    table = pa.Table.from_arrays([c if isinstance(c, pa.Array) else pa.array(c) for c in cols],
                                 schema=TRANSITION_SCHEMA)
    check_transitions(table)
    return table


def _matrix(column: pa.ChunkedArray | pa.Array, what: str) -> np.ndarray:
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if len(arr) == 0:
        return np.zeros((0, 0), np.float32)
    lengths = np.diff(arr.offsets.to_numpy())
    if lengths.min() != lengths.max():
        raise CorruptDatasetError(f"{what} rows have different lengths ({lengths.min()}..{lengths.max()})",
                                  hint="log the dataset again")
    values = arr.flatten().to_numpy(zero_copy_only=False)
    return values.reshape(len(arr), int(lengths[0])).astype(np.float32, copy=False)


def arrays(table: pa.Table) -> dict[str, np.ndarray]:
    """Every column as numpy (``obs``/``next_obs`` as float32[T, D])."""
    out = {}
    for f in TRANSITION_SCHEMA:
        col = table.column(f.name)
        out[f.name] = _matrix(col, f.name) if f.name in ("obs", "next_obs") else col.to_numpy()
    return out


def check_transitions(table: pa.Table, where: str = "transition table") -> None:
    """:class:`SchemaMismatchError` for another schema, :class:`CorruptDatasetError` for rows that do not form
    contiguous episodes with exactly one end flag each and ``next_obs[t] == obs[t+1]`` inside an episode."""
    diff = [n for n in TRANSITION_SCHEMA.names if n not in table.column_names]
    wrong = [f"{f.name}: {table.schema.field(f.name).type} (expected {f.type})" for f in TRANSITION_SCHEMA
             if f.name in table.column_names and table.schema.field(f.name).type != f.type]
    if diff or wrong:
        raise SchemaMismatchError(f"{where} does not match the transition schema v{TRANSITIONS_FORMAT}: "
                                  + "; ".join([f"missing column {n!r}" for n in diff] + wrong),
                                  hint="log the dataset again with this dtradar")
    a = arrays(table)
    n = len(a["action"])
    if n == 0:
        raise CorruptDatasetError(f"{where} has no rows", hint="log at least one step")

    def bad(msg: str):
        raise CorruptDatasetError(f"{where}: {msg}", hint="log the dataset again; never edit a transition table")

    ep, step = a["episode"], a["step"]
    new = np.r_[True, ep[1:] != ep[:-1]]
    if ep[0] != 0 or np.any(np.diff(ep) < 0) or np.any(np.diff(ep) > 1):
        bad("episodes are not numbered 0, 1, ... in order")
    starts = np.flatnonzero(new)
    expected_step = np.arange(n) - np.repeat(starts, np.diff(np.r_[starts, n]))
    if not np.array_equal(step, expected_step):
        bad("steps do not count 0, 1, ... within each episode")
    last = np.r_[new[1:], True]
    term, trunc = a["terminated"], a["truncated"]
    if np.any(term & trunc):
        bad(f"{int((term & trunc).sum())} steps are flagged both terminated and truncated")
    if np.any((term | trunc) != last):
        bad("an episode does not end in exactly one terminated or truncated step")
    if a["obs"].shape != a["next_obs"].shape:
        bad("obs and next_obs have different sizes")
    inner = ~last[:-1]
    if inner.any() and not np.array_equal(a["next_obs"][:-1][inner], a["obs"][1:][inner]):
        bad("next_obs[t] differs from obs[t+1] inside an episode (misaligned observations)")
    if np.any((a["action"] < 0) | (a["action"] > 3)):
        bad("actions outside 0..3")
    if not np.all(np.isfinite(a["reward"])) or not np.all(np.isfinite(a["obs"])):
        bad("non-finite rewards or observations")


def episode_stats(table: pa.Table, max_steps: int | None = None) -> dict[str, Any]:
    """Counts, the behaviour's success rate and its mean undiscounted return per episode.

    With ``max_steps`` (the step limit), a truncated episode shorter than it was cut by the end of logging, not
    failed: such episodes are counted (``cut_by_end_of_log``) but left out of the success rate and the mean return,
    which are over the *finished* episodes (target reached or step limit). ``reached_of_all`` counts the cut ones as
    failures: the two bracket the behaviour's true success when a log is short next to the step limit."""
    a = arrays(table)
    ep = a["episode"]
    returns = np.bincount(ep, weights=a["reward"].astype(np.float64))
    lengths = np.bincount(ep)
    n_ep = len(lengths)
    last = np.r_[ep[1:] != ep[:-1], True]
    term_ep = a["terminated"][last]
    cut = a["truncated"][last] & (lengths < max_steps) if max_steps else np.zeros(n_ep, bool)
    done = ~cut
    n_done = int(done.sum())
    return {"steps": int(len(ep)), "episodes": int(n_ep), "terminated": int(term_ep.sum()),
            "truncated": int(a["truncated"].sum()), "cut_by_end_of_log": int(cut.sum()),
            "success_rate": float(term_ep[done].sum() / max(1, n_done)),
            "reached_of_all": float(term_ep.sum() / max(1, n_ep)),
            "mean_return": float(returns[done].mean()) if n_done else 0.0,
            "mean_length": float(lengths[done].mean()) if n_done else 0.0, "obs_dim": int(a["obs"].shape[1]),
            "mean_reward": float(a["reward"].mean())}


# --------------------------------------------------------------------------------------------------------- version

def logging_inputs(*, parent: str, parent_version: str, behaviour: dict[str, Any], steps: int, seed: int,
                   settings: dict[str, Any], libraries: dict[str, str] | None = None) -> dict[str, Any]:
    """What a logged version hashes: parent (name and content version), behaviour and all its parameters, steps,
    seed, the environment settings (robots, observation preset, reward, step limit), format and libraries."""
    return {"parent": parent, "parent_version": parent_version, "behaviour": behaviour, "steps": int(steps),
            "seed": int(seed), "settings": settings, "format": TRANSITIONS_FORMAT,
            "library_versions": library_versions(LOGGED_LIBRARIES) if libraries is None else dict(libraries)}


def logged_version(inputs: dict[str, Any]) -> str:
    return version_id(inputs)


def table_digest(table: pa.Table) -> str:
    """A content hash of an in-memory table (for parents without a stored version, e.g. synthetic twins)."""
    import hashlib

    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema.remove_metadata()) as w:
        w.write_table(table.replace_schema_metadata(None))
    return "sha256:" + hashlib.sha256(sink.getvalue().to_pybytes()).hexdigest()[:16]


# ------------------------------------------------------------------------------------------------------------ card

def render_logged_card(meta: dict[str, Any], tag: str | None) -> str:
    """The Hugging Face dataset card (``README.md``) of a logged version: a pure function of its meta and tag."""
    from huggingface_hub import DatasetCard, DatasetCardData

    lid = parse_logged_id(meta["name"])
    stats = meta.get("stats") or {}
    data = DatasetCardData(
        license="apache-2.0", pretty_name=f"dtradar logged transitions {lid.name}",
        tags=["robotics", "reinforcement-learning", "offline-rl", "wireless", "digital-twin", "parquet", "minari"],
        task_categories=["reinforcement-learning"],
        configs=[{"config_name": "transitions", "data_files": TRANSITIONS_FILE, "default": True}],
        dtradar={"name": lid.name, "version": meta["version"], "tag": tag, "parent": meta["parent"],
                 "parent_version": meta["parent_version"], "format": TRANSITIONS_FORMAT})
    template = resources.files("dtradar_data.store").joinpath("templates/logged_card.md").read_text()
    files = meta.get("files") or {}
    beh = meta.get("behaviour") or {}
    card = DatasetCard.from_template(
        data, template_str=template, name=lid.name, version=meta["version"], tag=tag,
        created_utc=meta.get("created_utc"), parent=meta["parent"], parent_version=meta["parent_version"],
        behaviour=beh, behaviour_json=json.dumps(beh, sort_keys=True), behaviour_text=meta.get("behaviour_text", ""),
        steps=meta.get("steps"), seed=meta.get("seed"), settings=meta.get("settings") or {},
        stats=stats, obs=meta.get("observations") or {}, normalizer=json.dumps(meta.get("normalizer") or {}),
        minari=minari_id(lid, tag), columns=[(f.name, str(f.type), COLUMN_DESCRIPTIONS[f.name])
                                             for f in TRANSITION_SCHEMA],
        size=human_size((files.get(TRANSITIONS_FILE) or {}).get("bytes")), libraries=meta.get("library_versions") or {},
        version_hash_inputs=", ".join(sorted((meta.get("inputs") or {}).keys())))
    return str(card)


# --------------------------------------------------------------------------------------------------------- writing

def write_logged(name: str | LoggedId, inputs: dict[str, Any], table: pa.Table, meta: dict[str, Any]) -> tuple[str, Path]:
    """Store a logged version atomically (reused when it exists) and tag it; returns ``(version, directory)``.

    ``meta`` is stored in ``meta.json`` with the name, version, inputs, table stats, file hashes and creation time
    added; the card is rendered from it."""
    lid = parse_logged_id(name).with_revision(None)
    check_transitions(table)
    version = logged_version(inputs)
    ddir = logged_dir(lid)
    ddir.mkdir(parents=True, exist_ok=True)
    with FileLock(ddir / ".lock"):
        vdir = ddir / version
        refs = read_refs(_refs_path(lid))
        if not (vdir / P.META_FILE).is_file():
            if vdir.exists():
                shutil.rmtree(vdir)  # a leftover without meta.json never became a version
            P.work_root().mkdir(parents=True, exist_ok=True)
            stage = Path(tempfile.mkdtemp(prefix="logged-", dir=P.work_root()))
            try:
                full = {**json_safe(meta), "name": lid.name, "version": version, "format": TRANSITIONS_FORMAT,
                        "inputs": json_safe(inputs), "parent": inputs["parent"],
                        "parent_version": inputs["parent_version"], "behaviour": inputs["behaviour"],
                        "steps": inputs["steps"], "seed": inputs["seed"], "settings": inputs["settings"],
                        "library_versions": inputs["library_versions"],
                        "stats": {**episode_stats(table, (inputs.get("settings") or {}).get("max_steps")),
                                  **json_safe(meta.get("stats") or {})},
                        "created_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
                schema_meta = {META_KEY: json.dumps({"name": lid.name, "version": version}).encode()}
                pq.write_table(table.replace_schema_metadata(schema_meta), stage / TRANSITIONS_FILE,
                               compression="zstd", write_page_checksum=True)
                f = stage / TRANSITIONS_FILE
                full["files"] = {TRANSITIONS_FILE: {"sha256": sha256_file(f), "bytes": f.stat().st_size}}
                tag = refs.tag_of(version) or refs.next_tag()
                write_atomic(stage / P.META_FILE, json.dumps(full, indent=2, sort_keys=True) + "\n")
                write_atomic(stage / P.CARD_FILE, render_logged_card(full, tag))
                stage.rename(vdir)
            except BaseException:
                shutil.rmtree(stage, ignore_errors=True)
                raise
        if refs.tag_of(version) is None:
            refs = Refs({**refs.tags, refs.next_tag(): version}, version)
            write_refs(_refs_path(lid), refs)
    return version, vdir


def check_version_dir(vdir: Path) -> tuple[str, dict[str, Any]]:
    """Verify a version folder that is not (yet) in the store, e.g. a download: its record, the file's sha256, the
    table's invariants, and that the version is the hash of the recorded logging inputs. Returns ``(version, meta)``
    or raises :class:`CorruptDatasetError` / :class:`SchemaMismatchError`."""
    meta = _read_meta(vdir)
    version = meta.get("version")
    if not isinstance(meta.get("inputs"), dict) or logged_version(meta["inputs"]) != version:
        raise CorruptDatasetError(f"{vdir / P.META_FILE}: version {version!r} is not the hash of its logging inputs",
                                  hint="the record was edited or damaged; log or pull the dataset again")
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file() or sha256_file(f) != rec.get("sha256"):
        raise CorruptDatasetError(f"{f} is missing or its sha256 differs from meta.json",
                                  hint="log or pull the dataset again")
    read_transitions(f)
    return version, meta


def install_logged(name: str | LoggedId, staged: Path, *, preferred_tag: str | None = None) -> Path:
    """Move a verified version folder (:func:`check_version_dir`) into the store and tag it (``preferred_tag`` when
    it is free, e.g. the publisher's tag; else the next one). An existing version is kept; returns its folder."""
    lid = parse_logged_id(name).with_revision(None)
    version, meta = check_version_dir(staged)
    if meta.get("name") != lid.name:
        raise CorruptDatasetError(f"{staged} holds {meta.get('name')!r}, not {lid.name!r}",
                                  hint="pull it under its own name")
    ddir = logged_dir(lid)
    ddir.mkdir(parents=True, exist_ok=True)
    with FileLock(ddir / ".lock"):
        vdir = ddir / version
        if not (vdir / P.META_FILE).is_file():
            if vdir.exists():
                shutil.rmtree(vdir)
            shutil.move(str(staged), vdir)
        refs = read_refs(_refs_path(lid))
        if refs.tag_of(version) is None:
            tag = preferred_tag if preferred_tag and is_tag(preferred_tag) and preferred_tag not in refs.tags \
                else refs.next_tag()
            write_refs(_refs_path(lid), Refs({**refs.tags, tag: version}, version))
    return vdir


# --------------------------------------------------------------------------------------------------------- reading

@dataclass
class LoggedDataset:
    """One loaded logged version: the transition table and its metadata (``meta.json``)."""

    name: str
    version: str
    tag: str | None
    table: pa.Table
    meta: dict[str, Any]
    path: Path

    def __len__(self) -> int:
        return self.table.num_rows

    @property
    def frame(self):
        """The table as a polars DataFrame."""
        import polars as pl

        return pl.from_arrow(self.table)

    @property
    def id(self) -> LoggedId:
        return parse_logged_id(self.name).with_revision(self.tag or self.version)

    @property
    def minari_id(self) -> str:
        return minari_id(parse_logged_id(self.name), self.tag)

    def arrays(self) -> dict[str, np.ndarray]:
        return arrays(self.table)

    def __repr__(self) -> str:
        s = self.meta.get("stats") or {}
        return (f"LoggedDataset({self.name!r}, version={self.version!r}, tag={self.tag!r}, steps={len(self)}, "
                f"episodes={s.get('episodes')}, parent={self.meta.get('parent')!r})")


def _read_meta(vdir: Path) -> dict[str, Any]:
    try:
        meta = json.loads((vdir / P.META_FILE).read_text())
        if not isinstance(meta, dict) or meta.get("format") != TRANSITIONS_FORMAT:
            raise ValueError(f"format {meta.get('format') if isinstance(meta, dict) else None!r}, expected "
                             f"{TRANSITIONS_FORMAT}")
        return meta
    except (OSError, ValueError) as exc:
        raise CorruptDatasetError(f"{vdir / P.META_FILE} is not a logged-dataset record ({exc})",
                                  hint="log the dataset again (`python -m dtradar_rl log ...`)") from exc


def resolve_logged(name: str | LoggedId, revision: str | None = None) -> tuple[LoggedId, str, Path]:
    lid = parse_logged_id(name)
    revision = revision or lid.revision
    versions = local_versions(lid)
    if not versions:
        raise DatasetNotFoundError(f"logged dataset {lid.name} is not in {logged_root()}",
                                   hint=f"log it: `python -m dtradar_rl log --scene {lid.scene} --variant "
                                        f"{lid.variant} --behaviour {lid.behaviour}` (or `make logged`)")
    version = resolve_revision(read_refs(_refs_path(lid)), versions, revision, lid.name)
    return lid, version, logged_dir(lid) / version


def read_transitions(path: Path) -> pa.Table:
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise CorruptDatasetError(f"{path} cannot be read as Parquet ({exc})",
                                  hint="log the dataset again or re-pull it") from exc
    check_transitions(table.replace_schema_metadata(None), str(path))
    return table.replace_schema_metadata(None)


def load_logged(name: str | LoggedId, revision: str | None = None, *, verify: bool = True) -> LoggedDataset:
    """Load a logged version: the newest without ``revision`` (or ``@rev`` in ``name``), else a tag or hash.
    ``verify`` re-hashes the file against ``meta.json``; the table is always checked (:func:`check_transitions`)."""
    lid, version, vdir = resolve_logged(name, revision)
    meta = _read_meta(vdir)
    f = vdir / TRANSITIONS_FILE
    rec = (meta.get("files") or {}).get(TRANSITIONS_FILE) or {}
    if not f.is_file():
        raise CorruptDatasetError(f"{f} is missing", hint="log the dataset again")
    if verify and sha256_file(f) != rec.get("sha256"):
        raise CorruptDatasetError(f"{f}: sha256 differs from meta.json (changed or damaged)",
                                  hint=f"log it again, or remove {vdir}")
    table = read_transitions(f)
    tag = read_refs(_refs_path(lid)).tag_of(version)
    meta["tag"] = tag
    return LoggedDataset(lid.name, version, tag, table, meta, vdir)


def verify_logged(name: str | LoggedId, revision: str | None = None) -> dict[str, list[str]]:
    """``{version: problems}`` for one version or, without a revision, every version (empty list = fine)."""
    lid = parse_logged_id(name)
    if revision or lid.revision:
        versions = [resolve_logged(lid, revision)[1]]
    else:
        resolve_logged(lid)
        versions = local_versions(lid)
    out = {}
    for v in versions:
        problems = []
        try:
            load_logged(lid.with_revision(None), v)
        except (CorruptDatasetError, SchemaMismatchError) as exc:
            problems.append(exc.message)
        out[v] = problems
    return out


@dataclass(frozen=True)
class LoggedEntry:
    name: str
    version: str
    tag: str | None
    steps: int | None
    episodes: int | None
    success_rate: float | None
    parent: str
    path: Path


def list_logged() -> list[LoggedEntry]:
    """Every stored logged version, by name then tag."""
    root = logged_root()
    out = []
    if not root.is_dir():
        return out
    for bdir in sorted(root.glob("*/*/*")):
        if not bdir.is_dir() or not all(SCENE_RE.fullmatch(p) for p in bdir.relative_to(root).parts):
            continue
        try:
            lid = parse_logged_id("/".join(bdir.relative_to(root).parts))
        except UnknownNameError:
            continue
        refs = read_refs(_refs_path(lid))
        for v in local_versions(lid):
            try:
                meta = _read_meta(bdir / v)
            except CorruptDatasetError:
                meta = {}
            s = meta.get("stats") or {}
            out.append(LoggedEntry(lid.name, v, refs.tag_of(v), s.get("steps"), s.get("episodes"),
                                   s.get("success_rate"), meta.get("parent", lid.parent), bdir / v))
    return out


__all__ = ["GRAMMAR", "TRANSITION_SCHEMA", "LoggedDataset", "LoggedEntry", "LoggedId", "arrays", "check_transitions",
           "episode_stats", "format_logged_id", "is_logged_name", "list_logged", "load_logged", "logged_version",
           "logging_inputs", "minari_id", "check_version_dir", "install_logged", "parse_logged_id", "render_logged_card", "table_digest",
           "transitions_table", "verify_logged", "write_logged"]
