"""``python -m dtradar_rl offline-bench --executor ray`` without Ray installed is refused (exit status 2) before
anything is logged, and its hint names the executor that needs no Ray and that offline-bench accepts: ``--executor
local``. The hint was the sweep's, ``--executor serial``, which offline-bench refuses as an unknown choice."""

import sys

import pytest

from dtradar_data.core.errors import MissingDependencyError
from dtradar_rl.cli import main
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig
from dtradar_rl.experiments.offline_jobs import check_ray
from dtradar_rl.experiments.sweep import SweepConfig, _import_ray

TINY = [
    "--scene", "synthetic-8x6", "--behaviours", "random", "--algorithms", "bc", "--seeds", "0", "--variants",
    "blueprint", "--steps", "40", "--num-envs", "4", "--n-steps", "2", "--pairs", "4", "--no-fqe", "--no-tabular",
]  # fmt: skip


@pytest.fixture()
def no_ray(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError, as where it is not installed


def test_offline_bench_without_ray_is_refused_naming_executor_local(root, tmp_path, no_ray, capsys):
    out = tmp_path / "bench"
    assert main(["offline-bench", *TINY, "--executor", "ray", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "needs Ray, which is not installed" in err.splitlines()[0], err
    assert "--executor local" in err and "--executor serial" not in err, err
    assert "Traceback" not in err, err
    assert not (root / "logged").exists() and not out.exists()


def test_the_executor_each_hint_names_is_one_its_command_accepts(no_ray):
    with pytest.raises(MissingDependencyError) as bench:
        check_ray(None)
    assert "--executor local" in bench.value.hint
    OfflineBenchConfig(executor="local").validate()
    with pytest.raises(MissingDependencyError) as sweep:
        _import_ray()
    assert "--executor serial" in sweep.value.hint
    SweepConfig(executor="serial")
