"""The Minari copy of a logged dataset: written, checked, reused or rewritten, opened, and read back.

What the copy holds and where it lives is in :mod:`dtradar_rl.offline.formats` (Formats, Minari); this module does
it: :func:`export_minari` stages a copy and renames it into place (whole or absent), records it (``dtradar.json``)
and checks a stored one before reusing it (:func:`copy_state`); :func:`load_minari` opens it; reading a Minari
dataset back into our columns is :mod:`dtradar_rl.offline.minari_read`'s (:func:`from_minari`).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core import layout as P
from dtradar_data.core.files import sha256_file, waiting_lock
from dtradar_data.store import clean_stale_stages, held_stage
from dtradar_data.store.logged import (
    MINARI_DIR,
    MINARI_ENV,
    TRANSITIONS_FILE,
    LoggedDataset,
    LoggedId,
    minari_id,
    minari_root,
    parse_logged_id,
)
from dtradar_rl.offline.formats import as_logged
from dtradar_rl.offline.minari_envs import MinariEnvs, check_senses, env_text, minari_envs, minari_suffix
from dtradar_rl.offline.minari_read import from_minari, table_from_columns  # read back: here too, as before
from dtradar_rl.offline.minari_read import import_minari as _minari
from dtradar_rl.offline.minari_refs import reference_returns
from dtradar_rl.task.config import ConfigError


# -- Minari --------------------------------------------------------------------------------------------------------
def minari_episodes(a: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """Our rows as Minari episodes: ``observations`` ``L + 1`` rows, the rest ``L``."""
    ends = np.flatnonzero(a["terminated"] | a["truncated"]) + 1
    starts = np.r_[0, ends[:-1]]
    out = []
    for s, e in zip(starts, ends):
        out.append(
            {
                "observations": np.concatenate([a["obs"][s:e], a["next_obs"][e - 1 : e]]),
                "actions": a["action"][s:e].astype(np.int64),
                "rewards": a["reward"][s:e].astype(np.float64),
                "terminations": a["terminated"][s:e].astype(bool),
                "truncations": a["truncated"][s:e].astype(bool),
            }
        )
    return out


#: Minari's record of a namespace (``minari.namespace.NAMESPACE_METADATA_FILENAME``).
NAMESPACE_FILE = "namespace_metadata.json"
#: The record of a complete Minari copy, written beside its ``data/`` folder (Minari ignores it) as the copy's last
#: file before it is renamed into place: what it holds, where from, and the sha256 of every file of ``data/``.
RECORD_FILE = "dtradar.json"
#: 2: the copy records the env spec (``recover_environment``) and the env's observation space; 3: and Minari's
#: ``ref_min_score`` / ``ref_max_score`` (:mod:`dtradar_rl.offline.minari_refs`); an older copy is rewritten once.
RECORD_FORMAT = 3
#: Hidden (Minari lists no hidden folder) staging folders in the Minari path, held while written (see
#: :mod:`dtradar_data.store.logged.staging`).
STAGE_PREFIX = ".dtradar-stage-"


@contextlib.contextmanager
def _minari_path(path: Path):
    """Point Minari (which reads ``MINARI_DATASETS_PATH`` on every call) at ``path`` for the block. Not thread-safe:
    the process's environment is changed meanwhile."""
    old = os.environ.get(MINARI_ENV)
    os.environ[MINARI_ENV] = str(path)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(MINARI_ENV, None)
        else:
            os.environ[MINARI_ENV] = old


def _files(folder: Path) -> dict[str, str]:
    """``{path relative to folder: sha256}`` of the files of a copy's ``data/`` folder."""
    data = folder / "data"
    return {p.relative_to(folder).as_posix(): sha256_file(p) for p in sorted(data.rglob("*")) if p.is_file()}


def _record(folder: Path) -> dict[str, Any] | None:
    """The copy's record, of any format (an older one names its version too: see :func:`copy_state`)."""
    try:
        rec = json.loads((folder / RECORD_FILE).read_text())
        return rec if isinstance(rec, dict) and isinstance(rec.get("format"), int) else None
    except (OSError, ValueError):
        return None


def _minari_metadata(folder: Path) -> dict[str, Any] | None:
    try:
        meta = json.loads((folder / "data" / "metadata.json").read_text())
        return meta if isinstance(meta, dict) else None
    except (OSError, ValueError):
        return None


def copy_id(logged: LoggedDataset, senses: str = "none") -> str:
    """The Minari id of a copy: :attr:`LoggedDataset.minari_id`, and ``dtradar/<...>-memory-v<N>`` for the copy
    with the default agent's memory observations (``senses="memory"``)."""
    return _with_senses(logged.minari_id, senses)


def _with_senses(mid: str, senses: str) -> str:
    head, _, n = mid.rpartition("-v")
    return f"{head}{minari_suffix(senses)}-v{n}"


def _wanted(logged: LoggedDataset, senses: str = "none") -> dict[str, Any]:
    """What the record of ``logged``'s complete copy says (the files' hashes apart); a memory copy says so."""
    return {
        **({"senses": senses} if senses != "none" else {}),
        "format": RECORD_FORMAT,
        "name": logged.name,
        "version": logged.version,
        "tag": logged.tag,
        "transitions_sha256": ((logged.meta.get("files") or {}).get(TRANSITIONS_FILE) or {}).get("sha256"),
        "episodes": int((logged.meta.get("stats") or {}).get("episodes", -1)),
        "steps": len(logged),
        "data_root": str(P.data_root().absolute()),
    }


def copy_state(folder: Path, logged: LoggedDataset, senses: str = "none") -> tuple[str, str]:
    """``(state, why)`` of the Minari copy in ``folder`` next to ``logged``: ``"absent"``; ``"complete"`` (its
    record names this version, the same transitions file and episode count, and every file has its recorded
    sha256); ``"incomplete"`` (a write that was killed, damaged files, an older dtradar's copy without a record or
    with another record format (format 1: no env spec), or a copy written without an env spec because its twin
    was not here, which is now: to be rewritten); ``"other"`` (a complete copy of another logged version, by
    another data root whose tag still points at it: not ours to replace, whatever its format); ``"stale"`` (a copy
    of another version that no data root claims any more, e.g. this root's before its store was emptied:
    replaced); ``"foreign"`` (not written by dtradar)."""
    if not folder.exists():
        return "absent", ""
    want = _wanted(logged, senses)
    claim = minari_claim(folder, logged.name, logged.version, want["transitions_sha256"])
    if claim[0] != "ours":
        return claim
    rec = _record(folder)
    meta = _minari_metadata(folder)
    if rec is None:
        return "incomplete", f"{folder} has no complete {RECORD_FILE} (a killed write, or an older dtradar's copy)"
    if rec.get("format") != RECORD_FORMAT:
        return "incomplete", (
            f"{folder} was written by another dtradar (record format {rec.get('format')}, this one writes "
            f"{RECORD_FORMAT}: an env spec since format 2, reference scores since 3)"
        )
    if rec.get("senses", "none") != senses:
        return "incomplete", f"{folder} holds observations with senses {rec.get('senses', 'none')!r}, not {senses!r}"
    if rec.get("episodes") != want["episodes"] or rec.get("steps") != want["steps"]:
        return (
            "incomplete",
            f"{folder} records {rec.get('episodes')} episodes, the logged version has {want['episodes']}",
        )
    if meta is None or meta.get("total_episodes") != want["episodes"] or meta.get("total_steps") != want["steps"]:
        return "incomplete", f"{folder}: Minari's metadata does not count {want['episodes']} episodes"
    if _files(folder) != rec.get("files"):
        return "incomplete", f"{folder}: a file differs from its recorded sha256 (changed or damaged)"
    if rec.get("env_spec") is None and rec.get("env_retry") and minari_envs(logged, senses).spec is not None:
        return "incomplete", f"{folder} has no env spec ({rec.get('env_missing')}); the twin is here now"
    return "complete", ""


def minari_claim(folder: Path, name: str, version: str, transitions_sha256: str | None) -> tuple[str, str]:
    """Who ``folder`` belongs to, for a copy of logged version ``name@version`` (transitions file
    ``transitions_sha256``; None for a version not logged yet, compared by name and version only): ``("absent",
    "")``; ``("ours", "")`` (a copy of this version, or a record-less one dtradar left: :func:`copy_state` says
    whether it is whole); ``("other", why)`` (another version that another data root still holds: not ours to
    replace); ``("stale", why)`` (another version nobody holds any more); ``("foreign", why)`` (not dtradar's)."""
    if not folder.exists():
        return "absent", ""
    rec = _record(folder)
    if rec is None:
        meta = _minari_metadata(folder)
        if meta is not None and not str(meta.get("description") or "").startswith("dtradar "):
            return "foreign", f"{folder} was not written by dtradar ({str(meta.get('description'))[:60]!r})"
        return "ours", ""
    same = rec.get("name") == name and rec.get("version") == version
    if same and (transitions_sha256 is None or rec.get("transitions_sha256") == transitions_sha256):
        return "ours", ""
    root = Path(str(rec.get("data_root") or ""))
    here = str(P.data_root().absolute())
    held = rec.get("data_root") != here and _claimed(root, rec.get("name"), rec.get("tag"), rec.get("version"))
    what = f"{rec.get('name')}@{rec.get('tag')} (version {rec.get('version')}) of data root {root}"
    return ("other" if held else "stale"), what


def claimed_error(folder: Path, name: str, tag: str | None, state: str, why: str, done: str) -> ConfigError:
    """The refusal of a Minari copy of ``name@tag`` into ``folder``, which another data root's copy (``state``
    ``"other"``) or a dataset dtradar did not write (``"foreign"``) holds; ``done`` says what was (not) stored."""
    held = why if state == "other" else "a dataset dtradar did not write"
    return ConfigError(
        f"the Minari copy of {name}@{tag} cannot be written into {folder}: it holds {held}, and this data root "
        f"is {P.data_root().absolute()} ({done})",
        hint=f"give each data root its own Minari folder: unset {MINARI_ENV} (the copies then go to "
        f"<data root>/{MINARI_DIR}) or set it to another folder; or remove {folder}; or log without the copy "
        f'(`make log ... ARGS="--no-minari"`, `python -m dtradar_rl log ... --no-minari`)',
    )


def check_minari_free(
    name: str, version: str, tag: str, transitions_sha256: str | None = None, *, senses: str = "none"
) -> None:
    """Refuse (:func:`claimed_error`) before anything is logged or stored when the Minari copy of ``name@version``,
    to be tagged ``tag``, could not be written: its folder holds another data root's copy or a foreign dataset."""
    folder = minari_root() / _with_senses(minari_id(parse_logged_id(name), tag), senses)
    state, why = minari_claim(folder, name, version, transitions_sha256)
    if state in ("other", "foreign"):
        raise claimed_error(folder, name, tag, state, why, "nothing was logged or stored")


def _claimed(root: Path, name: Any, tag: Any, version: Any) -> bool:
    """Whether data root ``root`` still stores ``name`` with ``tag`` pointing at ``version``."""
    try:
        lid = parse_logged_id(str(name))
        refs = json.loads((root / "logged" / lid.scene / lid.variant / lid.behaviour / "refs.json").read_text())
        return isinstance(tag, str) and refs.get("tags", {}).get(tag) == version
    except (OSError, ValueError, KeyError, AttributeError):
        return False


def _write_copy(minari, stage: Path, mid: str, logged: LoggedDataset, envs: MinariEnvs | None = None) -> Path:
    """Write the Minari dataset ``mid`` of ``logged`` into the Minari path ``stage``, with the env specs of
    ``envs`` (default :func:`minari_envs`; without a spec, an unbounded observation space); returns its folder."""
    import gymnasium as gym
    from minari.data_collector import EpisodeBuffer

    envs = envs if envs is not None else minari_envs(logged)

    a = envs.arrays if envs.arrays is not None else logged.arrays()
    buffers = [
        EpisodeBuffer(
            id=i,
            observations=ep["observations"],
            actions=ep["actions"],
            rewards=list(ep["rewards"]),
            terminations=list(ep["terminations"]),
            truncations=list(ep["truncations"]),
        )
        for i, ep in enumerate(minari_episodes(a))
    ]
    d = a["obs"].shape[1]
    s = logged.meta.get("stats") or {}
    if envs.spec is not None:
        refs = reference_returns(envs.eval_spec)  # None on a moving twin: Minari's are optional
        env_args = {"env": envs.env, "eval_env": envs.eval_spec}
        if refs is not None:
            env_args.update(ref_min_score=refs["ref_min_score"], ref_max_score=refs["ref_max_score"])
        how = (
            f"recover_environment(): {env_text(envs.spec)}; recover_environment(eval_env=True): "
            f"{env_text(envs.eval_spec)} (import path {envs.spec.entry_point}, needs dtradar installed)"
        )
    else:
        env_args = {
            "observation_space": gym.spaces.Box(-np.inf, np.inf, (d,), np.float32),
            "action_space": gym.spaces.Discrete(4),
        }
        how = f"no env spec: {envs.missing}"
    with _minari_path(stage), contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # no author e-mail (and without a spec, no env): by design
        minari.create_dataset_from_buffers(
            dataset_id=mid,
            buffer=buffers,
            **env_args,
            algorithm_name=str((logged.meta.get("behaviour") or {}).get("kind")),
            author="dtradar",
            code_permalink="https://github.com/dtradar/dtradar",
            description=f"dtradar {logged.name} version {logged.version}; parent {logged.meta.get('parent')}@"
            f"{logged.meta.get('parent_version')}; behaviour success {s.get('success_rate', 0):.3f}; {how}; see "
            f"the dtradar card (README.md) at {logged.path}",
        )
    return stage / mid


def _ensure_namespace(stage: Path, root: Path, mid: str) -> None:
    """Give ``root`` the namespace record of ``mid`` (``<namespace>/namespace_metadata.json``) when it lacks it."""
    namespace = mid.rpartition("/")[0]
    if not namespace:
        return
    src = stage / namespace / NAMESPACE_FILE
    dst = root / namespace / NAMESPACE_FILE
    if src.is_file() and not dst.is_file():
        dst.parent.mkdir(parents=True, exist_ok=True)
        tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _remove_killed_stages(root: Path, say: Callable[[str], None]) -> None:
    """Remove the staging folders of killed writers of any copy in ``root`` (each as large as its copy), saying so:
    a stage whose lock is free has no live writer (:func:`~dtradar_data.store.clean_stale_stages`). Done on every
    export, a complete copy found too: the writer killed may have been another copy's, never written again."""
    gone = clean_stale_stages(root, STAGE_PREFIX, lockless=lambda _: True)  # .dtradar-stage-*: only ours
    if gone:
        say(f"removed what a killed Minari write left in {root}: {', '.join(p.name for p in gone)}")


def _rewriting(mid: str, state: str, why: str) -> str:
    """The line that says why the copy ``mid`` found in ``state`` is written again."""
    if state == "stale":
        return f"the Minari copy {mid} holds {why}, which no data root holds any more: replacing it"
    if state in ("other", "foreign"):
        return f"the Minari copy {mid} holds {why}: replacing it (overwrite)"
    return f"the Minari copy {mid} cannot be used: {why}; writing it again"


def export_minari(
    data: LoggedDataset | str | LoggedId,
    *,
    dataset_id: str | None = None,
    overwrite: bool = False,
    senses: str = "none",
    say: Callable[[str], None] = _stderr,
) -> str:
    """Write the Minari copy of a logged version into :func:`minari_root` and return its id.

    The copy appears whole or not at all: it is written into a hidden staging folder of the Minari path, recorded
    (``dtradar.json``: the version, the transitions file's sha256, the episode count, every data file's sha256)
    and renamed into place, under a lock per id (a second process says what it waits for, then finds the copy). A
    complete copy of the same version is kept; an incomplete or damaged one (a killed write, an older dtradar's
    copy) is rewritten; a copy of another version that another data root still holds under this id is refused
    (:class:`ConfigError`, naming ``MINARI_DATASETS_PATH`` and ``--no-minari``) unless ``overwrite``. A copy written
    again gets one line to ``say`` (default: stderr) naming why, as the stages of killed writers removed do.
    ``senses="memory"`` writes the copy whose observations carry the default agent's memory window and whose
    ``recover_environment()`` is the memory env (:func:`copy_id`: ``<id>-memory``; see
    :mod:`dtradar_rl.offline.minari_envs`)."""
    logged = as_logged(data)
    minari = _minari()
    mid = dataset_id or copy_id(logged, check_senses(senses))
    root = minari_root()
    folder = root / mid
    root.mkdir(parents=True, exist_ok=True)
    lock = root / f".dtradar-{mid.replace('/', '--')}.lock"
    with waiting_lock(lock, f"writing the Minari copy {mid}", then="this process uses that copy if it is whole"):
        _remove_killed_stages(root, say)
        state, why = copy_state(folder, logged, senses)
        if state == "complete":
            return mid
        if state in ("other", "foreign") and not overwrite:
            raise claimed_error(
                folder, logged.name, logged.tag, state, why, f"the logged dataset itself is stored in {logged.path}"
            )
        if state != "absent":
            say(_rewriting(mid, state, why))
        envs = minari_envs(logged, senses)
        if envs.spec is None:
            warnings.warn(
                f"the Minari copy {mid} records no env spec (recover_environment() will not work): {envs.missing}",
                UserWarning,
                stacklevel=2,
            )
        with held_stage(root, STAGE_PREFIX, lockless=lambda _: True) as stage:  # .dtradar-stage-*: only ours
            staged = _write_copy(minari, stage, mid, logged, envs)
            found = reference_returns(envs.eval_spec) if envs.spec is not None else None
            refs = found["references"] if found is not None else None
            rec = {
                **_wanted(logged, senses),
                "minari_id": mid,
                **envs.record(),
                "ref_scores": refs,
                "files": _files(staged),
            }
            (staged / RECORD_FILE).write_text(json.dumps(rec, indent=2, sort_keys=True) + "\n")
            _ensure_namespace(stage, root, mid)
            folder.parent.mkdir(parents=True, exist_ok=True)
            if folder.exists():  # incomplete, stale or (overwrite) another's: aside into the stage, removed with it
                os.rename(folder, stage / f"replaced-{folder.name}")
            os.rename(staged, folder)
    return mid


def load_minari(data: LoggedDataset | str | LoggedId, **export):
    """The ``MinariDataset`` of a logged version's Minari copy, written first when it is missing or incomplete
    (:func:`export_minari`); no ``MINARI_DATASETS_PATH`` needed."""
    mid = export_minari(as_logged(data), **export)
    from minari.dataset.minari_dataset import MinariDataset

    return MinariDataset(minari_root() / mid / "data")


__all__ = [
    "check_minari_free",
    "copy_id",
    "claimed_error",
    "copy_state",
    "export_minari",
    "from_minari",
    "load_minari",
    "minari_claim",
    "minari_episodes",
    "table_from_columns",
]
