"""--help prints each option's docstring as one paragraph, not broken where its source lines break."""

import os
import subprocess
import sys

import pytest
from tyro import _strings

from dtradar_data.core.help_text import join_docstring_lines

DOCSTRING = """goal relabelling of every run: auto (each algorithm's best measured mix, the
    default), none (the logged targets)
    - or a list item, which stays on its own line"""


def test_a_field_docstrings_indented_lines_are_joined_and_a_list_item_keeps_its_line():
    join_docstring_lines()
    join_docstring_lines()  # twice is once
    text = _strings.remove_single_line_breaks(DOCSTRING)
    assert text == (
        "goal relabelling of every run: auto (each algorithm's best measured mix, the default), none (the logged "
        "targets)\n- or a list item, which stays on its own line"
    )


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_the_command_lines_help_joins_a_multi_line_option_text():
    env = {**os.environ, "COLUMNS": "400"}
    out = subprocess.run(
        [sys.executable, "-m", "dtradar_rl", "offline-bench", "--help"], capture_output=True, text=True, env=env
    ).stdout
    assert "best measured mix, the default), none (the logged targets" in out
