"""`make help` names every target with one complete line (the first comment line above it)."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_help_gives_every_target_one_complete_line():
    out = subprocess.run(["make", "-s", "help"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    lines = {m.group(1): m.group(2).strip() for m in re.finditer(r"^  (\S+)\s+(.*)$", out, re.M)}
    targets = re.findall(r"^([a-z][a-z-]*):", (ROOT / "Makefile").read_text(), re.M)
    assert set(targets) <= set(lines), set(targets) - set(lines)
    cut = {t: d for t, d in lines.items() if not d or not re.search(r"[.)*/]$", d)}
    assert not cut, f"targets whose help line is empty or cut mid-sentence: {cut}"
