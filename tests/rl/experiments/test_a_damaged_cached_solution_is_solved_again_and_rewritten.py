"""``python -m dtradar_rl solve`` never serves a cached solution it cannot trust: each array file of the cache is
checked against the size and sha256 recorded beside it, and a damaged, short or missing one (or a cache written
before the hashes were recorded) is solved again, rewritten and named in one line on stderr. A tiny synthetic twin."""

import json
from pathlib import Path

import numpy as np
import pytest


def same_numbers(a: dict, b: dict) -> bool:
    return all(a[k] == b[k] for k in ("success_rate", "spl", "targets", "cells"))


@pytest.fixture()
def cached(root, tmp_path, capsys, solve):
    """``(row, folder, {file: its bytes})`` of a first solve, which wrote the cache."""
    row, _ = solve(tmp_path, capsys)
    assert not row["cached"]
    folder = Path(row["solution"])
    return row, folder, {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix in (".npy", ".json")}


def test_a_values_file_with_its_middle_third_overwritten_is_solved_again_and_rewritten(cached, tmp_path, capsys, solve):
    first, folder, files = cached
    data = bytearray(files["values.npy"])
    third = len(data) // 3
    data[third : 2 * third] = np.random.default_rng(0).bytes(third)
    (folder / "values.npy").write_bytes(bytes(data))

    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and same_numbers(row, first)
    assert f"{folder / 'values.npy'} does not match its content hash" in err and "solving it again" in err
    assert len(err.strip().splitlines()) == 1, err
    assert (folder / "values.npy").read_bytes() == files["values.npy"], "the cache is rewritten"
    row, err = solve(tmp_path, capsys)
    assert row["cached"] and same_numbers(row, first) and not err


def test_a_q_file_cut_in_half_is_noticed_and_rewritten(cached, tmp_path, capsys, solve):
    first, folder, files = cached
    (folder / "q.npy").write_bytes(files["q.npy"][: len(files["q.npy"]) // 2])

    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and same_numbers(row, first)
    assert f"{folder / 'q.npy'} has {len(files['q.npy']) // 2:,} bytes" in err and "solving it again" in err
    assert (folder / "q.npy").read_bytes() == files["q.npy"]
    assert solve(tmp_path, capsys)[0]["cached"]


@pytest.mark.parametrize("name", ["targets.npy", "cells.npy"])
def test_a_missing_array_file_is_named_and_solved_again(cached, tmp_path, capsys, name, solve):
    first, folder, files = cached
    (folder / name).unlink()
    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and same_numbers(row, first)
    assert f"{folder / name} is missing" in err
    assert (folder / name).read_bytes() == files[name]


def test_a_cache_written_before_content_hashes_is_solved_again_once_saying_so(cached, tmp_path, capsys, solve):
    first, folder, _ = cached
    meta = json.loads((folder / "solution.json").read_text())
    del meta["files"]  # what a dtradar before content hashes wrote
    (folder / "solution.json").write_text(json.dumps(meta))

    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and same_numbers(row, first)
    assert f"{folder / 'solution.json'} has no content hashes" in err
    row, err = solve(tmp_path, capsys)
    assert row["cached"] and not err, "once"


def test_a_sound_cache_is_served_quietly(cached, tmp_path, capsys, solve):
    first, _, _ = cached
    row, err = solve(tmp_path, capsys)
    assert row["cached"] and same_numbers(row, first) and not err
