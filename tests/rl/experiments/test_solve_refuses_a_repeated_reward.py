"""``python -m dtradar_rl solve`` refuses a repeated ``--rewards`` (or ``--variants``) when it is parsed, naming the
flag (``--rewards geodesic geodesic`` solved and printed the same row twice), before any twin is loaded or solved."""

import pytest

from dtradar_rl.cli import main
from dtradar_rl.experiments import solve
from dtradar_rl.experiments.solve import SolveConfig
from dtradar_rl.task.config import ConfigError

CASES = [
    (["--rewards", "geodesic", "geodesic"], "--rewards"),
    (["--rewards", "geodesic", "paper", "geodesic"], "--rewards"),
    (["--variants", "blueprint", "blueprint"], "--variants"),
]


@pytest.mark.parametrize("argv, flag", CASES, ids=[" ".join(a) for a, _ in CASES])
def test_a_repeated_reward_or_twin_is_refused_naming_its_flag_before_anything_is_solved(
    root, tmp_path, monkeypatch, capsys, argv, flag
):
    def loaded(*args, **kwargs):
        raise AssertionError("a twin was loaded with a setting that should have been refused first")

    monkeypatch.setattr(solve, "load_dataset", loaded)
    assert main(["solve", "--scene", "synthetic-12x8", *argv, "--out", str(tmp_path / "solve")]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and flag in first and "twice" in first, err
    assert "how to fix:" in err and "Traceback" not in err, err
    assert not (tmp_path / "solve").exists()
    with pytest.raises(ConfigError, match=flag):
        SolveConfig(**{flag[2:]: tuple(argv[1:])})
