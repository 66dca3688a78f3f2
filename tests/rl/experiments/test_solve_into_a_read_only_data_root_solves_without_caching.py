"""``python -m dtradar_rl solve`` with a read-only data root (a shared mirror, a container image): a solution not cached
there is solved for this run only, saying so (exit status 0, not a raw PermissionError); a sound cached one is read
from it; a damaged one is solved again without being rewritten, both said. Skipped where chmod does not stop writes
(as root). A tiny synthetic twin."""

from pathlib import Path


def test_a_solve_into_an_empty_read_only_data_root_solves_without_caching_and_says_so(
    root, read_only, tmp_path, capsys, solve
):
    read_only()
    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and row["success_rate"] == 1.0 and row["spl"] == 1.0
    assert f"{root} is read-only: solving without caching" in err
    assert list(root.iterdir()) == [], "nothing written"


def test_a_sound_cache_in_a_read_only_data_root_is_read_from_it(root, read_only, tmp_path, capsys, solve):
    first, _ = solve(tmp_path, capsys)
    folder = Path(first["solution"])
    (folder / ".q.npy.k1ll3d_0.tmp").write_bytes(b"a killed writer's")
    read_only()
    row, err = solve(tmp_path, capsys)
    assert row["cached"] and row["spl"] == first["spl"] and not err
    assert (folder / ".q.npy.k1ll3d_0.tmp").is_file(), "left as it is: nothing can be removed there"


def test_a_damaged_cache_in_a_read_only_data_root_is_solved_again_and_left_as_it_is(
    root, read_only, tmp_path, capsys, solve
):
    first, _ = solve(tmp_path, capsys)
    folder = Path(first["solution"])
    (folder / "q.npy").write_bytes((folder / "q.npy").read_bytes()[:100])
    read_only()
    row, err = solve(tmp_path, capsys)
    assert not row["cached"] and row["spl"] == first["spl"] == 1.0
    assert f"{folder / 'q.npy'} has 100 bytes" in err and f"{folder} is read-only: solving without caching" in err
    assert (folder / "q.npy").stat().st_size == 100
