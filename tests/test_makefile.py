"""The Makefile as users meet it: `make help` names every target with one complete line, and targets refuse what
would do the wrong thing silently."""

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
    raw = {t: d for t, d in lines.items() if "$(" in d}
    assert not raw, f"help lines showing a make variable unexpanded (the help writes $(SCENE) as <scene>): {raw}"
    columns = {line.index(d) for line in out.splitlines() if (d := line.split(maxsplit=1)[-1])}
    assert len(columns) == 1, "every description starts in the same column, after the longest target's name"


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_publish_refuses_without_a_name_instead_of_publishing_the_cubicle():
    refused = subprocess.run(["make", "-s", "publish"], cwd=ROOT, capture_output=True, text=True)
    assert refused.returncode != 0 and "NAME=<scene>/<variant>" in refused.stderr
    dry = subprocess.run(["make", "-n", "publish", "NAME=meeting/dynamic"], cwd=ROOT, capture_output=True, text=True)
    assert "dtradar_data publish meeting/dynamic" in dry.stdout
