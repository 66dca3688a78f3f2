"""Every command the tutorials and how-to guides show runs as shown.

Fast (in `make test`): every shell command of their fenced ``bash`` blocks is read as a shell would (continued lines
joined, comments dropped, ``&&`` split); a ``make`` command must name real Makefile targets, and the command lines
``make -n`` expands it to, like every ``python -m dtradar_data|dtradar_rl ...`` shown directly, must parse into their
command's config and pass its checks (``dtradar_data.cli.parse`` and ``dtradar_rl.cli.parse``: nothing runs). A
command of any other kind must be one of the few listed here, each with why it is not parsed. The checks run against an
empty data root, so a command may only fail them for a twin an earlier step of its page builds.

Slow (in `make test-all`): the tutorials' commands and Python blocks run in order, as written, in a temporary folder
with an empty data root, except the few that take minutes, each skipped with the reason."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dtradar_data.core.errors import DatasetNotFoundError

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted([*DOCS.glob("tutorials/*.md"), *DOCS.glob("how-to/*.md")])
PYTHONS = ("python", ".venv/bin/python")
#: Commands that are not ours to parse, and why.
NOT_PARSED = {
    ".venv/bin/python": "the interactive interpreter the tutorial's Python block is typed into",
    "python -c": "a one-line Python program (another library's API)",
    "export": "sets a shell variable",
    "bash": "a shell script for another machine (bench/gpu.sh); it must exist",
    "cp": "copies a file of this checkout; the file must exist",
}
#: A fenced block, at the start of a line or indented inside a list item (how-to steps are numbered lists).
FENCE = re.compile(r"^[ \t]*```(?:bash|sh|shell)\n(.*?)^[ \t]*```", re.M | re.S)
PY_FENCE = re.compile(r"^[ \t]*```python\n(.*?)^[ \t]*```", re.M | re.S)


def shell_commands(page: Path) -> list[list[str]]:
    """The commands of ``page``'s bash blocks, each as its words (``a && b`` gives two)."""
    commands = []
    for block in FENCE.findall(page.read_text(encoding="utf-8")):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            while words:
                cut = words.index("&&") if "&&" in words else len(words)
                commands.append(words[:cut])
                words = words[cut + 1 :]
    return commands


def all_commands() -> list[tuple[str, list[str]]]:
    return [(f"{p.parent.name}/{p.name}", c) for p in PAGES for c in shell_commands(p)]


def makefile_targets() -> set[str]:
    return set(re.findall(r"^([a-z][a-z-]*):", (ROOT / "Makefile").read_text(), re.M))


#: Files a command reads that an earlier step of its page writes (a checkpoint, a map): made empty for the check.
INPUT_FILE = re.compile(r"[\w./-]+\.(pt|osm|geojson)")


def parse_cli(words: list[str], cwd: Path | None = None) -> None:
    """Parse ``python -m <package> <args>`` into its command's config and check it, running nothing (``--help``: its
    help, which must exit 0), in ``cwd`` with the input files it names there (empty)."""
    package, args = words[2], words[3:]
    for a in args:
        if cwd is not None and INPUT_FILE.fullmatch(a) and not (ROOT / a).exists():
            (cwd / a).parent.mkdir(parents=True, exist_ok=True)
            (cwd / a).touch()
    if package == "dtradar_rl":
        from dtradar_rl.cli import parse
    elif package == "dtradar_data":
        from dtradar_data.cli import parse
    else:
        raise AssertionError(f"python -m {package}: not one of dtradar's CLIs")
    with (
        contextlib.chdir(cwd or ROOT),
        contextlib.redirect_stdout(io.StringIO()),
        contextlib.redirect_stderr(io.StringIO()) as err,
    ):
        try:
            parse(args)
        except DatasetNotFoundError:  # a twin the page builds in an earlier step: the command itself checked out
            pass
        except SystemExit as e:  # tyro: --help (0) or a usage error (2, its message on stderr)
            assert e.code == 0 and "--help" in args, f"{shlex.join(words)}: {err.getvalue()[-2000:]}"


def is_cli(words: list[str]) -> bool:
    return len(words) > 3 and words[0] in PYTHONS and words[1] == "-m" and words[2].startswith("dtradar_")


def make_dry_run(words: list[str]) -> list[list[str]]:
    """The command lines ``make -n`` would run for ``make <words>`` (``PY=python``), as words."""
    out = subprocess.run(
        ["make", "-n", "-s", "-f", str(ROOT / "Makefile"), "PY=python", *words[1:]],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, f"{shlex.join(words)}: make -n failed: {out.stderr}"
    return [shlex.split(line) for line in out.stdout.splitlines() if line.strip() and not line.startswith("make")]


@pytest.mark.parametrize("page,words", all_commands(), ids=[f"{p}:{shlex.join(c)[:60]}" for p, c in all_commands()])
def test_every_command_of_the_tutorials_and_how_tos_parses(page, words, tmp_path, root):
    """Checked against an empty data root (``root``): a command that needs a twin built first may say so, and only
    so (a ``DatasetNotFoundError``)."""
    if words[0] == "make":
        assert shutil.which("make"), "needs make"
        targets = [w for w in words[1:] if "=" not in w and not w.startswith("-")]
        assert targets and set(targets) <= makefile_targets(), f"{page}: no such make target in {words}"
        for line in make_dry_run(words):
            if is_cli(line):
                parse_cli(line, tmp_path)
    elif is_cli(words):
        parse_cli(words, tmp_path)
    else:
        kind = " ".join(words[:2]) if words[:2] == ["python", "-c"] else words[0]
        assert kind in NOT_PARSED, f"{page}: {shlex.join(words)} is neither make nor a dtradar CLI (add it or run it)"
        if kind in ("bash", "cp"):
            assert (ROOT / words[1]).is_file(), f"{page}: {words[1]} does not exist"


def test_the_docs_show_commands_of_every_kind_checked_here():
    """The extraction finds the pages' commands (an empty parse would pass every test above)."""
    commands = all_commands()
    assert len(commands) > 50
    assert any(c[0] == "make" for _, c in commands) and any(is_cli(c) for _, c in commands)


def test_a_bad_option_or_value_in_a_command_fails_the_check():
    with pytest.raises(AssertionError):
        parse_cli(["python", "-m", "dtradar_rl", "offline", "--no-such-option"])
    with pytest.raises(Exception, match="algorithm"):
        parse_cli(["python", "-m", "dtradar_rl", "offline", "--algorithm", "sac"])
    with pytest.raises(AssertionError):
        parse_cli(["python", "-m", "dtradar_data", "info"])  # no name


# The slow test: the tutorials run as written.

#: Commands of the tutorials not run, with why (each takes minutes on 2 cores, or changes this checkout).
NOT_RUN = {
    "make setup": "creates the virtual environment this test runs in",
    "make test": "the test suite this test is part of",
}
TUTORIALS = ("first-twin", "first-agent", "first-offline-benchmark")


def tutorial_steps(name: str) -> list[tuple[str, object]]:
    """The page's bash commands and Python blocks, in the page's order."""
    text = (DOCS / "tutorials" / f"{name}.md").read_text(encoding="utf-8")
    blocks = sorted(
        [(m.start(), "bash", m.group(1)) for m in FENCE.finditer(text)]
        + [(m.start(), "python", m.group(1)) for m in PY_FENCE.finditer(text)]
    )
    steps: list[tuple[str, object]] = []
    for _, kind, body in blocks:
        if kind == "python":
            steps.append(("python", textwrap.dedent(body)))
            continue
        for line in body.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words:
                steps.append(("bash", words))
    return steps


@pytest.mark.slow
@pytest.mark.sionna
@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
@pytest.mark.skipif(importlib.util.find_spec("sionna") is None, reason="make dataset needs Sionna RT")
def test_the_tutorials_run_as_written(tmp_path):
    """first-twin, first-agent, first-offline-benchmark in order: their commands (through this checkout's Makefile,
    in a temporary folder, so runs/ and results/ land there) and their Python blocks, in one data root."""
    env = {**os.environ, "DTRADAR_DATA_ROOT": str(tmp_path / "data"), "MINARI_DATASETS_PATH": str(tmp_path / "minari")}
    namespace: dict = {}
    ran = []
    for name in TUTORIALS:
        for kind, step in tutorial_steps(name):
            if kind == "python":
                code = compile(step, f"docs/tutorials/{name}.md", "exec")
                with contextlib.chdir(tmp_path), pytest.MonkeyPatch.context() as mp:
                    mp.setenv("DTRADAR_DATA_ROOT", env["DTRADAR_DATA_ROOT"])
                    exec(code, namespace)
                ran.append(f"{name}: python block")
                continue
            words = step
            line = shlex.join(words).replace("'", "")
            if line in NOT_RUN or words == [".venv/bin/python"]:
                continue  # not run (NOT_RUN says why), or the interpreter the Python blocks stand for
            if words[0] == "make":
                cmd = ["make", "-s", "-f", str(ROOT / "Makefile"), f"PY={sys.executable}", *words[1:]]
            else:
                assert is_cli(words), f"{name}: {shlex.join(words)}: not a command this test can run"
                cmd = [sys.executable, *words[1:]]
            done = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, (
                f"{name}: {shlex.join(words)} failed:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
            )
            ran.append(f"{name}: {line}")
    assert (tmp_path / "runs" / "cubicle" / "agent" / "agent.json").is_file()
    assert (tmp_path / "runs" / "cubicle" / "dqn" / "model.pt").is_file()  # the learnt agent, trained as written
    assert (tmp_path / "runs" / "cubicle" / "offline" / "bc" / "results.json").is_file()
    bench = json.loads((tmp_path / "results" / "offline_bench" / "cubicle-radio" / "bench.json").read_text())
    assert {(r["behaviour"], r["algorithm"]) for r in bench["runs"]} == {
        (b, a) for b in ("random", "expert") for a in ("bc", "cql")
    }  # the tutorial's benchmark, honest sensing, run as written
    assert len(ran) >= 10, ran
