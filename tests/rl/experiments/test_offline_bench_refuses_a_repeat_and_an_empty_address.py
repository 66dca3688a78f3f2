"""``python -m dtradar_rl offline-bench`` refuses what would be counted twice or silently mean something else, naming
its flag, before anything is logged or trained: a repeated seed (``--seeds 0 0`` averaged one run counted twice), a
repeated algorithm, behaviour or twin; and an empty ``--ray-address`` (``""`` started a local Ray, as leaving the flag
out does)."""

import pytest

from dtradar_rl.cli import main
from dtradar_rl.experiments import offline_bench
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig
from dtradar_rl.task.config import ConfigError

SCENE = ["--scene", "synthetic-8x6"]


@pytest.fixture()
def nothing_runs(monkeypatch):
    def ran(*args, **kwargs):
        raise AssertionError("the benchmark ran with a setting that should have been refused first")

    monkeypatch.setattr(offline_bench, "run_bench", ran)


def refused(capsys, argv: list[str], flag: str) -> str:
    assert main(["offline-bench", *SCENE, *argv]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and flag in first, err
    assert "how to fix:" in err and "Traceback" not in err and "unexpected" not in err, err
    return err


REPEATS = [
    (["--seeds", "0", "0"], "--seeds"),
    (["--seeds", "0", "1", "0"], "--seeds"),
    (["--algorithms", "bc", "bc"], "--algorithms"),
    (["--behaviours", "expert", "expert"], "--behaviours"),
    (["--variants", "blueprint", "blueprint"], "--variants"),
]


@pytest.mark.parametrize("argv, flag", REPEATS, ids=[" ".join(a) for a, _ in REPEATS])
def test_a_repeated_value_is_refused_naming_its_flag(root, nothing_runs, capsys, argv, flag):
    err = refused(capsys, argv, flag)
    assert "twice" in err
    with pytest.raises(ConfigError, match=flag):
        OfflineBenchConfig(**{flag[2:]: tuple(int(v) if v.isdigit() else v for v in argv[1:])})


@pytest.mark.parametrize("address", ["", "  "])
def test_an_empty_ray_address_is_refused_and_says_how_to_give_one_or_drop_it(root, nothing_runs, capsys, address):
    err = refused(capsys, ["--executor", "ray", "--ray-address", address], "--ray-address")
    assert "drop --ray-address" in err
    with pytest.raises(ConfigError, match="--ray-address"):
        OfflineBenchConfig(executor="ray", ray_address=address).validate()
