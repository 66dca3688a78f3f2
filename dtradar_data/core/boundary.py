"""The one error boundary of both command lines (``python -m dtradar_data`` and ``python -m dtradar_rl``).

Exit codes: 0 success; 1 a check that ran and failed (``verify``, ``cards --check``); 2 a bad input or any typed
:class:`~dtradar_data.core.errors.DtradarError` (and tyro's own usage errors); 3 an unexpected exception, that is a
bug: one ``error: unexpected ...`` line instead of a traceback; 130 interrupted (Ctrl-C). ``--debug`` anywhere on
the command line (or ``DTRADAR_DEBUG=1``) prints the full traceback as well. A reader that closes the output early
(``... | head``) ends the command quietly with 141, as a shell reports SIGPIPE: not a success, not a bug.
"""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable, Sequence

from .errors import DtradarError

EXIT_OK = 0
EXIT_FAILED_CHECK = 1
EXIT_ERROR = 2
EXIT_BUG = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141

DEBUG_FLAG = "--debug"
DEBUG_ENV = "DTRADAR_DEBUG"
#: For the --help text of both CLIs (tyro never sees the flag: it is taken off the command line first).
DEBUG_HELP = (
    f"Add {DEBUG_FLAG} anywhere (or set {DEBUG_ENV}=1) to see the traceback of an error. "
    "Exit status: 0 ok, 1 a failed check, 2 a bad input, 3 an unexpected error (a bug), 130 interrupted."
)


def split_debug(argv: Sequence[str] | None) -> tuple[list[str], bool]:
    """``argv`` (default ``sys.argv[1:]``) without ``--debug`` (before any ``--``), and whether debugging is on."""
    args = list(sys.argv[1:] if argv is None else argv)
    end = args.index("--") if "--" in args else len(args)
    debug = DEBUG_FLAG in args[:end]
    args = [a for a in args[:end] if a != DEBUG_FLAG] + args[end:]
    return args, debug or os.environ.get(DEBUG_ENV, "").strip().lower() not in ("", "0", "false", "no")


def _one_line(exc: BaseException, limit: int = 400) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def run_cli(command: Callable[[list[str]], int | None], argv: Sequence[str] | None = None) -> int:
    """Run ``command(args)`` (the CLI's parse-and-run, given the command line without ``--debug``) and turn every
    failure into an exit status and a short message on stderr; ``SystemExit`` (tyro's usage errors, ``--help``)
    passes through unchanged."""
    args, debug = split_debug(argv)
    try:
        try:
            return command(args) or EXIT_OK
        finally:  # --help and tyro's SystemExit included: a closed pipe shows here, not at the interpreter's exit
            sys.stdout.flush()
    except DtradarError as exc:
        if debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except BrokenPipeError:
        if debug:
            traceback.print_exc()
        try:  # stdout's reader has gone: point stdout at /dev/null so the interpreter's final flush stays quiet
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return EXIT_BROKEN_PIPE
    except KeyboardInterrupt:
        if debug:
            traceback.print_exc()
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the boundary: anything else is a bug, reported in one line
        if debug:
            traceback.print_exc()
            print(f"error: unexpected {type(exc).__name__}: {_one_line(exc)}", file=sys.stderr)
        else:
            detail = _one_line(exc)
            print(
                f"error: unexpected {type(exc).__name__}{': ' + detail if detail else ''} "
                f"(run again with {DEBUG_FLAG} for the traceback)",
                file=sys.stderr,
            )
        return EXIT_BUG
