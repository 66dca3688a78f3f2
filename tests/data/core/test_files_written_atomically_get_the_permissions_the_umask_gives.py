"""A file written through open_atomic gets the mode open() would give it (0666 less the umask), not the 0600 of
tempfile.mkstemp: a shared mirror's files must be readable by everyone the umask lets read them."""

import os
import stat
from contextlib import contextmanager

import pytest

from dtradar_data.core.files import open_atomic, temp_siblings, write_atomic


@contextmanager
def umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_a_file_written_atomically_has_the_mode_its_umask_gives(tmp_path, mask, mode):
    with umask(mask):
        write_atomic(tmp_path / "meta.json", "{}\n")
        with open_atomic(tmp_path / "values.npy", "wb") as f:
            f.write(b"\x00" * 16)
        with open(tmp_path / "plain.txt", "w") as f:  # what open() gives under the same umask
            f.write("x")
    for name in ("meta.json", "values.npy", "plain.txt"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def test_a_rewritten_file_takes_the_umask_mode_and_leaves_no_temp_file(tmp_path):
    path = tmp_path / "record.json"
    with umask(0o022):
        write_atomic(path, "old\n")
        os.chmod(path, 0o600)
        write_atomic(path, "new\n")
    assert path.read_text() == "new\n"
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert temp_siblings(path) == []


def test_the_temp_file_of_a_writer_matches_the_shape_killed_writers_are_found_by(tmp_path):
    path = tmp_path / "q.npy"
    with open_atomic(path, "wb") as f:
        seen = temp_siblings(path)
        f.write(b"x")
    assert len(seen) == 1 and seen[0].name.startswith(".q.npy.") and seen[0].name.endswith(".tmp")
    assert temp_siblings(path) == []
