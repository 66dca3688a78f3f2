"""``python -m dtradar_data`` / ``dtradar-data``: build, list, inspect, verify, card, publish and pull datasets.

Generated with tyro from frozen dataclasses (the field docstrings are the ``--help`` text), one subcommand each.
Typed errors (:class:`~dtradar_data.core.errors.DtradarError`) print as one ``error: ...`` line plus how to fix it and
exit with status 2; a failed ``verify`` or ``cards --check`` exits with status 1; anything unexpected prints one line
and exits with status 3 (``--debug`` shows its traceback): see :mod:`dtradar_data.core.boundary`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from dtradar_data.core.boundary import DEBUG_HELP, EXIT_FAILED_CHECK, run_cli
from dtradar_data.core.errors import DtradarError, InvalidSettingError
from dtradar_data.core.files import human_size
from dtradar_data.core.layout import data_root
from dtradar_data.pipeline import builder
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.publish import cards, hub, logged_hub
from dtradar_data.rt import llvm
from dtradar_data.rt.tracer import smoke_test
from dtradar_data.store import listing, local
from dtradar_data.store.catalog import as_any_id
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
            print(
                json.dumps(
                    [
                        {
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
                            "damaged": [
                                {"tag": v.tag, "version": v.version, "path": str(v.path), "problem": v.problem}
                                for v in r.damaged
                            ],
                        }
                        for r in rows
                    ]
                    + _logged_json(),
                    indent=2,
                )
            )
            return 0
        print(f"data root: {data_root()}")
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
        logged = list_logged()
        healthy = [e for e in logged if e.problem is None]
        if healthy:  # offline-RL datasets logged on the twins (scene/variant/behaviour)
            print(f"\n{'logged dataset':<40} {'tag':<5} {'version':<18} {'steps':>8} {'episodes':>8} {'success':>8}")
            for e in healthy:
                ok = f"{e.success_rate:.3f}" if e.success_rate is not None else "-"
                print(
                    f"{e.name:<40} {e.tag or '-':<5} {e.version:<18} {e.steps or '-':>8} {e.episodes or '-':>8} {ok:>8}"
                )
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
    variant = " VARIANT=moving" if parsed.variant == "moving" else ""
    return (
        f"rebuild them (`make dataset SCENE={parsed.scene}{variant}`) or re-pull them "
        f"(`python -m dtradar_data pull {parsed.name}@<tag>`)"
    )


@dataclass(frozen=True)
class CardsCmd:
    """Refresh the committed dataset cards (cards/<scene>/<variant>/) from the local store, then check them all."""

    names: tuple[str, ...] = ()
    """Datasets to refresh (default: every built-in dataset that is built here; others are left as committed)."""
    out: Path = Path("cards")
    """Directory holding the committed cards."""
    check: bool = False
    """Only check: exit 1 if a committed README.md differs from what its card.json renders to."""
    rerender: bool = False
    """Re-render every committed card from its card.json (after a template change; no datasets needed)."""

    def run(self) -> int:
        if not self.check:
            if self.rerender:
                for d in cards.rerender(self.out):
                    print(f"re-rendered {d / 'README.md'}")
            else:
                written, skipped = cards.write_builtin_cards(self.out, list(self.names) or None)
                for d in written:
                    print(f"wrote {d / 'README.md'}")
                for name in skipped:
                    print(f"skipped {name}: not built here (`make dataset SCENE={name.split('/')[0]}`)")
        stale = cards.stale_cards(self.out)
        for d in stale:
            print(f"stale: {d / 'README.md'} (run `make cards`)", file=sys.stderr)
        if not stale:
            print(f"{len(cards.committed_cards(self.out))} committed cards are up to date")
        return EXIT_FAILED_CHECK if stale else 0


@dataclass(frozen=True)
class PublishCmd:
    """Upload one dataset version to a Hugging Face Hub dataset repo (one commit, tagged)."""

    name: Name
    """Dataset id, e.g. cubicle/blueprint (newest version) or cubicle/blueprint@v0."""
    revision: Revision = None
    """Tag or version hash to publish; default: the newest."""
    repo: Annotated[str | None, tyro.conf.arg(metavar="OWNER/NAME")] = None
    """Hub dataset repo id; default dtradar/dtradar-<scene>-<variant>. Needs a token (HF_TOKEN or `hf auth login`)."""
    private: bool = False
    """Create the repo as private if it does not exist."""

    def run(self) -> int:
        publish = logged_hub.publish if is_logged_name(self.name) else hub.publish
        result = publish(self.name, self.revision, repo_id=self.repo, private=self.private)
        print(result.describe())
        return 0


@dataclass(frozen=True)
class PullCmd:
    """Download a published dataset version from the Hub into the local store (verified, then moved into place)."""

    name: Name
    """Dataset id, e.g. cubicle/blueprint@v0; without a revision, the Hub's newest (main)."""
    revision: Revision = None
    """Tag or version hash to pull."""
    repo: Annotated[str | None, tyro.conf.arg(metavar="OWNER/NAME")] = None
    """Hub dataset repo id; default dtradar/dtradar-<scene>-<variant>."""

    def run(self) -> int:
        pull = logged_hub.pull if is_logged_name(self.name) else hub.pull
        path = pull(self.name, self.revision, repo_id=self.repo)
        print(f"pulled into {path}")
        return 0


@dataclass(frozen=True)
class CheckCmd:
    """Check the ray-tracing backend: find a libLLVM for Dr.Jit and run one JIT-compiled kernel (`make setup` ends
    with this)."""

    def run(self) -> int:
        print(f"libLLVM for Dr.Jit: {llvm.configure()}")
        print(smoke_test())
        return 0


def run_build(cfg: BuildConfig) -> int:
    for ds in builder.build(cfg):
        tag = ds.meta.get("tag")
        print(f"{ds.name}@{tag or ds.version}: version {ds.version}, {ds.table.num_rows} cells, {ds.path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (console scripts and ``__main__`` pass it to ``sys.exit``); the exit
    codes and ``--debug`` are :mod:`dtradar_data.core.boundary`'s."""
    return run_cli(_parse_and_run, argv)


def _parse_and_run(argv: list[str]) -> int:
    commands = {
        "build": BuildConfig,
        "list": ListCmd,
        "info": InfoCmd,
        "verify": VerifyCmd,
        "cards": CardsCmd,
        "publish": PublishCmd,
        "pull": PullCmd,
        "check": CheckCmd,
    }
    cfg = parse_command(
        commands,
        argv,
        prog="python -m dtradar_data",
        description="Sionna RT digital-twin datasets: build, list, inspect, verify, card, publish, pull. " + DEBUG_HELP,
    )
    return run_build(cfg) if isinstance(cfg, BuildConfig) else cfg.run()


def parse_command(commands: dict[str, type], argv: list[str], **kwargs) -> object:
    """tyro's parse of ``argv`` into one of ``commands``, with every refusal of a value a typed error.

    A config's own check (its ``__post_init__``: :class:`~dtradar_data.rt.settings.RTSettings`, ``BuildConfig``)
    raises a :class:`DtradarError` whose message names the flag; tyro would catch it (it is a ``ValueError``) and
    print it in a box titled with its internal name of the config (``Error parsing __tyro-dummy-inner__.rt``,
    ``Error parsing BuildConfig``). Here it reaches the error boundary as itself instead: one ``error: ...`` line,
    how to fix it, exit status 2. tyro's own usage errors (an unknown flag, ``x`` for a number) and ``--help`` are
    tyro's, printed as before. Then :func:`check_finite` refuses a NaN or an infinity in any number flag."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):  # tyro prints its box before it exits: held back until known
            cfg = tyro.extras.subcommand_cli_from_dict(commands, args=argv, **kwargs)
    except SystemExit as exc:
        typed = _typed_cause(exc)
        if typed is not None:
            raise typed from None
        sys.stderr.write(captured.getvalue())
        raise
    sys.stderr.write(captured.getvalue())
    check_finite(cfg)
    return cfg


def _typed_cause(exc: BaseException) -> DtradarError | None:
    """The :class:`DtradarError` a (tyro) exception was raised while handling, if any."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, DtradarError):
            return cause
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return None


def check_finite(cfg: object, prefix: str = "--") -> None:
    """:class:`InvalidSettingError` for a NaN or an infinity in any float flag of a parsed command (``--cell-m nan``,
    ``--tx inf 0 20``, ``--rt.frequency-hz nan``): no flag of either command line means one, and a NaN passes every
    range check (``nan < 0`` is false) to surface later as a wrong result or an internal error."""
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        flag = prefix + f.name.replace("_", "-")
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            check_finite(value, flag + ".")
            continue
        values = value if isinstance(value, tuple) else (value,)
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            raise InvalidSettingError(
                f"{flag} {' '.join(str(v) for v in values)}: not a finite number (nan and inf are no flag's value)",
                hint=f"give {flag} finite numbers; `--help` after the command lists what each flag takes",
            )
