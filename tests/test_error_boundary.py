"""One error boundary per CLI (``dtradar_data.core.boundary``): a typed error exits 2 with its message and fix, an
unexpected exception (a bug) exits 3 with one line pointing at ``--debug``, ``--debug`` (or ``DTRADAR_DEBUG=1``)
shows the traceback, Ctrl-C exits 130, a reader that closes the output early exits 141 quietly. The commands are
made to fail by replacing something they call; nothing is traced or trained."""

import os
import subprocess
import sys

import pytest

from dtradar_data import cli as data_cli
from dtradar_data.core.boundary import EXIT_BROKEN_PIPE, EXIT_BUG, EXIT_ERROR, EXIT_INTERRUPTED, split_debug
from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.store import listing
from dtradar_rl import cli as rl_cli
from dtradar_rl.evaluation import jobs as eval_jobs

# (the CLI, a command line, the module attribute the command calls first)
COMMANDS = {
    "dtradar_data list": (data_cli.main, ["list"], listing, "list_datasets"),
    "dtradar_rl eval": (rl_cli.main, ["eval", "--scene", "synthetic"], eval_jobs, "load_agent_or_policy"),
}


def raising(exc: BaseException):
    def call(*args, **kwargs):
        raise exc

    return call


@pytest.fixture(params=sorted(COMMANDS))
def command(request, root, monkeypatch):
    """(main, argv, make_it_raise) for each CLI; ``make_it_raise(exc)`` makes the command's first call raise."""
    monkeypatch.delenv("DTRADAR_DEBUG", raising=False)
    main, argv, module, attribute = COMMANDS[request.param]
    return main, argv, lambda exc: monkeypatch.setattr(module, attribute, raising(exc))


def test_an_unexpected_exception_is_one_line_pointing_at_debug_and_exit_status_3(command, capsys):
    main, argv, make_it_raise = command
    make_it_raise(ZeroDivisionError("division by zero"))
    assert main(argv) == EXIT_BUG == 3
    captured = capsys.readouterr()
    assert captured.err == (
        "error: unexpected ZeroDivisionError: division by zero (run again with --debug for the traceback)\n"
    )
    assert "Traceback" not in captured.out


def test_a_multi_line_or_empty_message_still_gives_one_line(command, capsys):
    main, argv, make_it_raise = command
    make_it_raise(RuntimeError("first\nsecond\n  third"))
    assert main(argv) == EXIT_BUG
    assert capsys.readouterr().err == (
        "error: unexpected RuntimeError: first second third (run again with --debug for the traceback)\n"
    )
    make_it_raise(AssertionError())
    assert main(argv) == EXIT_BUG
    assert capsys.readouterr().err == "error: unexpected AssertionError (run again with --debug for the traceback)\n"


@pytest.mark.parametrize("where", ["first", "last"])
def test_debug_anywhere_on_the_command_line_shows_the_traceback(command, capsys, where):
    main, argv, make_it_raise = command
    make_it_raise(ZeroDivisionError("division by zero"))
    assert main(["--debug", *argv] if where == "first" else [*argv, "--debug"]) == EXIT_BUG
    err = capsys.readouterr().err
    assert err.startswith("Traceback (most recent call last):") and "in call" in err
    assert err.endswith("error: unexpected ZeroDivisionError: division by zero\n")


def test_the_dtradar_debug_environment_variable_shows_the_traceback_too(command, capsys, monkeypatch):
    main, argv, make_it_raise = command
    make_it_raise(ZeroDivisionError("division by zero"))
    monkeypatch.setenv("DTRADAR_DEBUG", "1")
    assert main(argv) == EXIT_BUG
    assert "Traceback (most recent call last):" in capsys.readouterr().err
    monkeypatch.setenv("DTRADAR_DEBUG", "0")
    assert main(argv) == EXIT_BUG
    assert "Traceback" not in capsys.readouterr().err


def test_a_typed_error_still_exits_2_with_its_fix_and_debug_adds_the_traceback(command, capsys):
    main, argv, make_it_raise = command
    make_it_raise(DatasetNotFoundError("nothing here", hint="build it"))
    assert main(argv) == EXIT_ERROR == 2
    assert capsys.readouterr().err == "error: nothing here\n  how to fix: build it\n"
    assert main([*argv, "--debug"]) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "Traceback" in err and err.endswith("error: nothing here\n  how to fix: build it\n")


def test_ctrl_c_exits_130_with_one_word(command, capsys):
    main, argv, make_it_raise = command
    make_it_raise(KeyboardInterrupt())
    assert main(argv) == EXIT_INTERRUPTED == 130
    assert capsys.readouterr().err == "interrupted\n"


def test_debug_changes_nothing_for_a_command_that_works(root, capsys):
    assert data_cli.main(["list"]) == 0
    plain = capsys.readouterr()
    assert data_cli.main(["list", "--debug"]) == 0
    assert capsys.readouterr() == plain


def test_debug_after_a_double_dash_is_left_for_the_command():
    assert split_debug(["list", "--", "--debug"]) == (["list", "--", "--debug"], False)
    assert split_debug(["--debug", "list", "--debug"])[0] == ["list"]


def test_help_and_usage_errors_keep_tyros_exit_status(root, capsys):
    with pytest.raises(SystemExit) as exit_:
        data_cli.main(["--help"])
    assert exit_.value.code == 0 and "--debug" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:
        rl_cli.main(["no-such-command"])
    assert exit_.value.code == 2


# The process's own exit status, through ``python -m``: the bug is planted before the module runs.
PLANTED = (
    "import runpy, dtradar_data.store.listing as listing\n"
    "def bug(*a, **k): raise ZeroDivisionError('division by zero')\n"
    "listing.list_datasets = bug\n"
    "runpy.run_module('dtradar_data', run_name='__main__')\n"
)


@pytest.mark.parametrize("debug", [False, True])
def test_python_m_dtradar_data_exits_3_on_a_bug(root, debug):
    env = {k: v for k, v in os.environ.items() if k != "DTRADAR_DEBUG"}
    run = subprocess.run(
        [sys.executable, "-c", PLANTED, "list", *(["--debug"] if debug else [])],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert run.returncode == 3, run.stderr
    assert ("Traceback" in run.stderr) is debug
    assert run.stderr.splitlines()[-1].startswith("error: unexpected ZeroDivisionError: division by zero")


def test_a_reader_that_closes_the_output_early_ends_the_command_quietly_with_141(root):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # buffered: flushed at the end
    read, write = os.pipe()
    os.close(read)  # `... | head -0`
    try:
        run = subprocess.run(
            [sys.executable, "-m", "dtradar_data", "list"],
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            timeout=60,
        )
    finally:
        os.close(write)
    assert run.returncode == EXIT_BROKEN_PIPE == 141
    assert run.stderr == ""
