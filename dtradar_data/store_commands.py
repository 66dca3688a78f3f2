"""The commands of ``python -m dtradar_data`` that read the local store: ``list``, ``info`` and ``verify``.

Each is a frozen dataclass that :mod:`dtradar_data.cli` makes a subcommand (with tyro: the field docstrings are the
``--help`` text), for the ray-traced datasets and the logged ones alike (a logged dataset's name has a third part,
``cubicle/blueprint/noisy-shortest``). A damaged version is listed, not fatal; ``verify`` exits with status 1 when a
version fails and says how to get it back (the build or log command that makes it, or a pull). A version another
process is building or logging right now is unfinished, not damaged: ``verify`` names that process (its pid) instead
(:mod:`dtradar_data.store.writers`).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from typing import Annotated

import tyro

from dtradar_data.core.boundary import EXIT_FAILED_CHECK
from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import human_size
from dtradar_data.core.layout import data_root
from dtradar_data.core.layout import refs_path as refs_path_of
from dtradar_data.store import listing, local
from dtradar_data.store.catalog import as_any_id, build_command
from dtradar_data.store.logged import (
    LoggedId,
    is_logged_name,
    list_logged,
    local_versions,
    log_commands,
    logged_dir,
    minari_id,
    minari_root,
    parse_logged_id,
    read_meta,
    refs_path,
    relog_hint,
    resolve_logged,
)
from dtradar_data.store.versions import read_refs
from dtradar_data.store.writers import being_written

__all__ = ["InfoCmd", "ListCmd", "Name", "Revision", "VerifyCmd"]

#: A positional dataset id argument, shown as NAME in --help (the Makefile passes it positionally).
Name = Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="NAME")]
Revision = Annotated["str | None", tyro.conf.arg(metavar="TAG|HASH")]


@dataclass(frozen=True)
class ListCmd:
    """List the built-in datasets and every version stored in the data root."""

    json: bool = False
    """Print JSON instead of a table."""

    def run(self) -> int:
        rows = listing.list_datasets()
        if self.json:
            print(json.dumps([_dataset_json(r) for r in rows] + _logged_json(), indent=2))
            return 0
        print(f"data root: {data_root()}")
        _print_datasets(rows)
        logged = list_logged()
        _print_logged([e for e in logged if e.problem is None])
        damaged = [(r.name, v.tag, v.version, v.problem) for r in rows for v in r.damaged]
        damaged += [(e.name, e.tag, e.version, e.problem) for e in logged if e.problem is not None]
        for name, tag, version, problem in damaged:
            print(f"DAMAGED {name}@{tag or version}: {problem}")
        if damaged:  # listed, not fatal: the healthy versions stay usable
            print(
                f"{len(damaged)} damaged version(s): `python -m dtradar_data verify NAME` shows every problem and "
                "the command that makes each again; remove, rebuild (log) or re-pull them",
                file=sys.stderr,
            )
        return 0


def _dataset_json(r) -> dict:
    """One RT dataset's row of ``list --json``: its versions and its damaged ones."""
    return {
        "name": r.name,
        "builtin": r.builtin,
        "latest": r.latest,
        "versions": [
            {
                "tag": v.tag,
                "version": v.version,
                "created_utc": v.created_utc,
                "rows": v.num_rows,
                "bytes": v.size_bytes,
            }
            for v in r.versions
        ],
        "damaged": [{"tag": v.tag, "version": v.version, "path": str(v.path), "problem": v.problem} for v in r.damaged],
    }


def _print_datasets(rows) -> None:
    """``list``'s table of RT datasets: every version's tag, the newest's hash, rows and size."""
    w = max([24, *(len(r.name) for r in rows)])  # names like sionna-san_francisco/blueprint are long
    print(f"{'dataset':<{w}} {'versions':<20} {'latest':<22} {'rows':>8} {'size':>10}")
    for r in rows:
        latest = next((v for v in r.versions if v.version == r.latest), None)
        tags = ",".join(v.tag or v.version[:7] for v in r.versions) or "(not built)"
        shown = f"{latest.tag} {latest.version[:12]}" if latest else "-"
        print(
            f"{r.name:<{w}} {tags:<20} {shown:<22} {latest.num_rows if latest else '-':>8} "
            f"{human_size(latest.size_bytes) if latest else '-':>10}"
        )


def _print_logged(healthy) -> None:
    """``list``'s table of the healthy logged datasets (none: no table)."""
    if healthy:  # offline-RL datasets logged on the twins (scene/variant/behaviour)
        print(f"\n{'logged dataset':<40} {'tag':<5} {'version':<18} {'steps':>8} {'episodes':>8} {'success':>8}")
        for e in healthy:
            ok = f"{e.success_rate:.3f}" if e.success_rate is not None else "-"
            print(f"{e.name:<40} {e.tag or '-':<5} {e.version:<18} {e.steps or '-':>8} {e.episodes or '-':>8} {ok:>8}")


def _logged_json() -> list[dict]:
    """The logged datasets of ``list --json``: one row per name, shaped like an RT dataset's row."""
    out: dict[str, dict] = {}
    for e in list_logged():
        row = out.setdefault(
            e.name,
            {
                "name": e.name,
                "kind": "logged",
                "parent": e.parent,
                "builtin": False,
                "latest": read_refs(refs_path(parse_logged_id(e.name))).latest,
                "versions": [],
                "damaged": [],
            },
        )
        if e.problem is None:
            row["versions"].append(
                {
                    "tag": e.tag,
                    "version": e.version,
                    "created_utc": e.created_utc,
                    "rows": e.steps,
                    "bytes": e.size_bytes,
                    "episodes": e.episodes,
                    "success_rate": e.success_rate,
                }
            )
        else:
            row["damaged"].append({"tag": e.tag, "version": e.version, "path": str(e.path), "problem": e.problem})
    for row in out.values():
        if row["latest"] not in {v["version"] for v in row["versions"]}:
            row["latest"] = row["versions"][-1]["version"] if row["versions"] else None
    return list(out.values())


def _logged_info(name: str, revision: str | None) -> int:
    """``info`` of a logged dataset: its card's key facts, its Minari copy, every version (damaged ones flagged)."""
    lid = as_any_id(name)
    # a named revision, or a dataset whose versions are all damaged: resolve among the damaged ones too, so the
    # error names the damaged file instead of "not in the store"
    damaged = bool(revision or lid.revision) or not local_versions(lid)
    lid, version, vdir = resolve_logged(lid, revision, damaged=damaged)
    meta = read_meta(vdir)
    tag = read_refs(refs_path(lid)).tag_of(version)
    stats, settings, beh = meta.get("stats") or {}, meta.get("settings") or {}, meta.get("behaviour") or {}
    print(f"{lid.name}@{tag or version}  (version {version}, logged dataset, format v{meta.get('format')})")
    print(f"  parent:      {meta.get('parent')} @ {meta.get('parent_version')}")
    print(f"  behaviour:   {json.dumps(beh, sort_keys=True)}")
    print(f"  created:     {meta.get('created_utc', '-')}")
    print(
        f"  steps:       {stats.get('steps', '-')} in {stats.get('episodes', '-')} episodes "
        f"({stats.get('terminated', '-')} reached the target, {stats.get('truncated', '-')} truncated)"
    )
    success = stats.get("success_rate")
    print(f"  success:     {'-' if success is None else f'{success:.3f}'} (behaviour, finished episodes)")
    print("  settings:    " + ", ".join(f"{k}={v}" for k, v in sorted(settings.items())) + f", seed={meta.get('seed')}")
    print(f"  path:        {vdir}")
    for fname, rec in sorted((meta.get("files") or {}).items()):
        print(f"    {fname:<20} {human_size(int(rec.get('bytes', 0))):>10}  sha256 {rec.get('sha256', '')[:16]}")
    mid = minari_id(lid, tag)
    folder = minari_root() / mid
    there = "written" if (folder / "data").is_dir() else f"not written (`{log_commands(lid, meta)[0]}` writes it)"
    print(f"  minari:      {mid} in {folder.parent.parent}: {there}")
    print("  versions:")
    for e in list_logged():
        if e.name == lid.name:
            mark = "*" if e.version == version else " "
            state = f"DAMAGED: {e.problem}" if e.problem else f"{e.created_utc or '-':<22} {e.steps or '-':>8} steps"
            print(f"   {mark} {e.tag or '-':<4} {e.version}  {state}")
    return 0


@dataclass(frozen=True)
class InfoCmd:
    """Summarise one dataset: its card's key facts, every version, file sizes."""

    name: Name
    """Dataset id, e.g. cubicle/blueprint or cubicle/blueprint@v0 (a logged one: cubicle/blueprint/noisy-shortest)."""
    revision: Revision = None
    """Tag (v0, v1, ...) or version hash; default: the newest version."""

    def run(self) -> int:
        if is_logged_name(self.name):
            return _logged_info(self.name, self.revision)
        did, version, vdir = local.resolve(self.name, self.revision)
        meta = local.read_meta(vdir)
        grid, rt, stats = meta.get("grid", {}), meta.get("rt", {}), meta.get("stats", {})
        tag = next((v.tag for v in listing.version_infos(did) if v.version == version), None)
        print(f"{did.name}@{tag or version}  (version {version}, schema v{meta.get('schema_version')})")
        print(f"  title:       {meta.get('title') or (meta.get('scene_spec') or {}).get('title', '-')}")
        print(f"  created:     {meta.get('created_utc', '-')}")
        print(
            f"  grid:        {grid.get('nx')} x {grid.get('ny')} cells of {grid.get('cell_m')} m, "
            f"origin ({grid.get('x0_m')}, {grid.get('y0_m')})"
        )
        print(
            f"  cells:       {stats.get('num_cells', '-')} ({stats.get('num_free', '-')} free, "
            f"{stats.get('num_with_paths', '-')} with paths)"
        )
        _moving_info(meta)
        keys = ("frequency_hz", "max_depth", "samples_per_src", "seed")
        print("  rt:          " + ", ".join(f"{k}={rt[k]}" for k in keys if k in rt))
        print(f"  licence:     {meta.get('licence') or (meta.get('scene_spec') or {}).get('licence', '-')}")
        print(f"  path:        {vdir}")
        for fname, rec in sorted((meta.get("files") or {}).items()):
            print(f"    {fname:<16} {human_size(int(rec.get('bytes', 0))):>10}  sha256 {rec.get('sha256', '')[:16]}")
        print("  versions:")
        for v in listing.version_infos(did):
            mark = "*" if v.version == version else " "
            print(f"   {mark} {v.tag or '-':<4} {v.version}  {v.created_utc or '-':<26} {human_size(v.size_bytes):>10}")
        return 0


def _moving_info(meta: dict) -> None:
    """``info``'s lines about a moving twin: snapshots, movers, and how many cells each snapshot re-traced."""
    moving = meta.get("moving")
    if not isinstance(moving, dict):
        return
    build = meta.get("moving_build") or {}
    snapshots, dt_s = moving.get("snapshots"), moving.get("dt_s")
    print(f"  moving:      {snapshots} snapshots, {dt_s} s apart; movers: {', '.join(moving.get('movers') or [])}")
    if build:
        print(
            f"  traced:      snapshot 0 in full ({build.get('full_seconds')} s), the others differentially from the "
            f"one before (radius {build.get('radius_m')} m): {build.get('retraced_cells_mean')} of "
            f"{build.get('free_cells_mean')} free cells per snapshot on average, "
            f"{build.get('differential_seconds_mean')} s each"
        )


@dataclass(frozen=True)
class VerifyCmd:
    """Re-hash every file of a dataset's versions against meta.json and check the Parquet schemas."""

    name: Name
    """Dataset id, e.g. cubicle/blueprint (all versions) or cubicle/blueprint@v0 (one); a logged one alike
    (cubicle/blueprint/noisy-shortest)."""
    revision: Revision = None
    """Only this tag or version hash."""

    def run(self) -> int:
        results = listing.verify(self.name, self.revision)
        bad = [version for version, problems in results.items() if problems]
        for version, problems in results.items():
            print(f"{version}: {'ok' if not problems else 'FAILED'}")
            for p in problems:
                print(f"  - {p}")
        if not (self.revision or "@" in self.name):
            for version, who in being_written(self.name).items():
                if version not in results:  # unfinished, neither ok nor failed
                    print(f"{version}: being written by {who}; not verified, run verify again once it has finished")
        if bad:
            print(f"{len(bad)} of {len(results)} versions failed; {_fix_hint(self.name, bad)}", file=sys.stderr)
        return EXIT_FAILED_CHECK if bad else 0


def _fix_hint(name: str, bad: list[str]) -> str:
    """How to get failed versions back: the command that makes them (an RT build or a log), or a pull."""
    parsed = as_any_id(name, check_known=False)
    if isinstance(parsed, LoggedId):
        lid = parsed.with_revision(None)
        try:
            meta = read_meta(logged_dir(lid) / bad[0])
        except DtradarError:
            meta = None  # no readable record: the generic command
        pull = f"`python -m dtradar_data pull {lid.name}@<tag>`"
        folder = str(logged_dir(lid) / bad[0]) if len(bad) == 1 else None
        return f"{relog_hint(lid, meta, folder)}; or re-pull a published one ({pull})"
    one = len(bad) == 1  # one failed version: its own tag (or hash) in the pull
    revision = (read_refs(refs_path_of(parsed.scene, parsed.variant)).tag_of(bad[0]) or bad[0]) if one else "<tag>"
    them = "it" if one else "them"
    return (
        f"rebuild {them} with {build_command(parsed)} or re-pull {them} "
        f"(`python -m dtradar_data pull {parsed.name}@{revision}`)"
    )
