"""Help text of the command lines, as one paragraph per option.

tyro keeps a line break before every line that does not start with a letter, and a field docstring's continuation
lines start with their indentation, so ``--help`` broke each option's text where its docstring's source lines broke
(tyro 1.0.17). Its line joiner is given the docstring dedented the way Python's own ``inspect.cleandoc`` reads a
docstring; a line starting with a non-letter after the dedent ("- item", "(see ...)") still starts a new line, as
tyro means it to."""

from __future__ import annotations

import inspect

from tyro import _strings  # tyro's own joiner, called through its module by the docstring, field and parser code


def join_docstring_lines() -> None:
    """Make tyro join a field docstring's lines (idempotent; the two command lines call it on import)."""
    original = _strings.remove_single_line_breaks
    if getattr(original, "dedents_first", False):
        return

    def remove_single_line_breaks(helptext: str) -> str:
        return original(inspect.cleandoc(helptext))

    remove_single_line_breaks.dedents_first = True  # type: ignore[attr-defined]
    _strings.remove_single_line_breaks = remove_single_line_breaks
