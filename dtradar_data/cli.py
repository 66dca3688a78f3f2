"""``python -m dtradar_data`` / ``dtradar-data``: build, list, inspect, verify, card, publish and pull datasets.

Generated with tyro from frozen dataclasses (the field docstrings are the ``--help`` text), one subcommand each:
``build`` (:class:`~dtradar_data.pipeline.config.BuildConfig`), the commands that read the local store (``list``,
``info``, ``verify``: :mod:`dtradar_data.store_commands`), and here the ones that write cards, talk to the Hub or
check the backend (``cards``, ``publish``, ``pull``, ``check``), the entry point and the parse that keeps every
refusal of a value a typed error. Typed errors (:class:`~dtradar_data.core.errors.DtradarError`) print as one
``error: ...`` line plus how to fix it and exit with status 2; a failed ``verify`` or ``cards --check`` exits with
status 1; anything unexpected prints one line and exits with status 3 (``--debug`` shows its traceback): see
:mod:`dtradar_data.core.boundary`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from dtradar_data.channels.export import ChannelsCmd
from dtradar_data.core.boundary import DEBUG_HELP, EXIT_FAILED_CHECK, run_cli
from dtradar_data.core.errors import DtradarError, InvalidSettingError
from dtradar_data.core.help_text import join_docstring_lines
from dtradar_data.pipeline import builder
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.publish import cards, hub, logged_hub
from dtradar_data.rt import llvm
from dtradar_data.rt.tracer import smoke_test
from dtradar_data.store.logged import is_logged_name
from dtradar_data.store_commands import InfoCmd, ListCmd, Name, Revision, VerifyCmd

join_docstring_lines()


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
        pull = logged_hub.pull_version if is_logged_name(self.name) else hub.pull_version
        print(pull(self.name, self.revision, repo_id=self.repo).describe())
        return 0


@dataclass(frozen=True)
class CheckCmd:
    """Check the ray-tracing backend: find a libLLVM for Dr.Jit and run one JIT-compiled kernel (`make setup` ends
    with this)."""

    def run(self) -> int:
        print(f"libLLVM for Dr.Jit: {llvm.configure()}")
        print(smoke_test())
        return 0


@dataclass(frozen=True)
class PlaceCmd:
    """Print transmitter sites for a scene's blueprint as [[tx]] tables: greedy line-of-sight coverage of its free
    cells (dtradar_data.scenes.placement), each site where it sees the most cells no other site sees."""

    scene: tyro.conf.Positional[str]
    """A built-in scene, sionna:<name> or a scene file."""
    range_m: float = 150.0
    """How far a site sees, metres."""
    height_m: float = 10.0
    """The transmitters' height above the ground, metres (printed; line of sight on the plan ignores it)."""
    coverage: float = 0.99
    """Stop once this share of the free cells is seen."""
    max_sites: int = 16
    """Stop after this many sites (the kept one included)."""
    clearance_cells: int = 1
    """A site's cells within this many cells (a square) must all be free: 0 allows a site against a wall."""
    keep: bool = False
    """Keep the scene's own transmitter as the first site."""
    heard_in: str | None = None
    """A built twin of the scene, <scene>/<variant>[@revision]: its cells with a path count as covered, so the sites
    go where its trace found none (a second round)."""

    def __post_init__(self) -> None:
        # checked when parsed, before the scene is read: out of range, each used to print sites (exit 0) or fail inside
        if not 0 < self.coverage <= 1:
            raise InvalidSettingError(
                f"--coverage {self.coverage} must be in (0, 1]: it is the share of the free cells to see",
                hint="e.g. --coverage 0.99 (the default), or 1 to place sites until every free cell is seen",
            )
        if self.max_sites < 1:
            raise InvalidSettingError(
                f"--max-sites {self.max_sites} must be >= 1 (the kept site included)", hint="e.g. --max-sites 16"
            )
        if not self.range_m > 0:
            raise InvalidSettingError(
                f"--range-m {self.range_m} must be > 0: it is how far a site sees, in metres",
                hint="e.g. --range-m 150 (the default)",
            )
        if self.clearance_cells < 0:
            raise InvalidSettingError(
                f"--clearance-cells {self.clearance_cells} must be >= 0",
                hint="0 allows a site against a wall; 1 (the default) keeps the cells around it free",
            )
        if self.heard_in is not None and (not self.heard_in.strip() or is_logged_name(self.heard_in)):
            raise InvalidSettingError(
                f"--heard-in {self.heard_in!r} is not a ray-traced twin: --heard-in takes a built twin of the scene, "
                "<scene>/<variant>[@revision]"
                + (" (a logged offline-RL dataset has no paths to count)" if self.heard_in.strip() else ""),
                hint="name a twin built on this scene's grid, e.g. --heard-in cubicle/blueprint "
                "(`python -m dtradar_data list` shows the built ones)",
            )

    def run(self) -> int:
        from dtradar_data.geometry.occupancy import occupancy
        from dtradar_data.publish.loading import load
        from dtradar_data.scenes import load_scene_spec
        from dtradar_data.scenes.placement import place_sites

        spec = load_scene_spec(self.scene, "blueprint")
        blocked = occupancy(spec)
        xs, ys = spec.grid.centres()
        start = ()
        if self.keep:
            ix, iy = spec.grid.index_of(*spec.tx.position_m[:2])
            start = (iy * blocked.shape[1] + ix,)
        covered = None
        if self.heard_in is not None:
            heard = load(self.heard_in).heard()
            if heard.shape != blocked.shape:
                raise InvalidSettingError(
                    f"--heard-in {self.heard_in} has a {heard.shape[1]} x {heard.shape[0]} grid and {self.scene} a "
                    f"{blocked.shape[1]} x {blocked.shape[0]} one",
                    hint="name a dataset built on this scene's grid (a twin of it with other transmitters)",
                )
            covered = heard & ~blocked
        sites, share = place_sites(
            blocked,
            range_cells=self.range_m / spec.grid.cell_m,
            coverage=self.coverage,
            max_sites=self.max_sites,
            clearance_cells=self.clearance_cells,
            start=start,
            covered=covered,
        )
        print(f"# {len(sites)} sites: {share:.3f} of {int((~blocked).sum())} free cells seen or heard")
        for k, site in enumerate(sites[len(start) :], start=len(start)):
            iy, ix = divmod(site, blocked.shape[1])
            print(f'[[tx]]\nname = "tx{k}"\nposition_m = [{xs[ix]:.1f}, {ys[iy]:.1f}, {self.height_m:.1f}]')
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
    cfg = parse(argv)
    return run_build(cfg) if isinstance(cfg, BuildConfig) else cfg.run()


def parse(argv: list[str]) -> object:
    """The command ``argv`` names, parsed and checked as values (the errors :func:`parse_command` raises), with
    nothing run: a :class:`BuildConfig`, or a command object whose ``run()`` does the work. The docs' commands are
    checked with it (tests/test_docs_commands.py)."""
    commands = {
        "build": BuildConfig,
        "list": ListCmd,
        "info": InfoCmd,
        "verify": VerifyCmd,
        "cards": CardsCmd,
        "publish": PublishCmd,
        "pull": PullCmd,
        "check": CheckCmd,
        "place": PlaceCmd,
        "channels": ChannelsCmd,
    }
    return parse_command(
        commands,
        argv,
        prog="python -m dtradar_data",
        description="Sionna RT digital-twin datasets: build, list, inspect, verify, card, publish, pull, place; "
        "generate channels from a stored one. " + DEBUG_HELP,
    )


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
