"""Sweeps: several seeds trained and evaluated on a local Ray cluster come back as one table with mean and spread."""

import json

import pytest

from dtradar_rl.cli import main
from dtradar_rl.experiments.sweep import SweepConfig, summarise, sweep
from dtradar_rl.task.config import ConfigError

TINY = dict(scenes=("synthetic-8x6",), preset="tuned", total_env_steps=3_000, pairs=20)


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_a_sweep_of_two_seeds_on_ray_returns_both_results(tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        result = sweep(SweepConfig(**TINY, seeds=(0, 1), out=str(tmp_path)))
    finally:
        ray.shutdown()
    assert sorted(r["seed"] for r in result["runs"]) == [0, 1]
    assert {e["evaluated_on"] for e in result["summary"]} == {"synthetic-8x6/blueprint", "synthetic-8x6/dynamic"}
    assert all(e["seeds"] == 2 for e in result["summary"])
    for name in ("sweep.json", "sweep.md", "sweep.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert (tmp_path / "synthetic-8x6" / "seed1" / "model.pt").is_file()


def test_the_serial_executor_runs_without_ray_from_the_command_line(tmp_path, capsys):
    args = [
        "sweep",
        "--scenes",
        "synthetic-8x6",
        "--seeds",
        "3",
        "--executor",
        "serial",
        "--total-env-steps",
        "2000",
        "--pairs",
        "10",
        "--variants",
        "blueprint",
        "--out",
        str(tmp_path),
    ]
    assert main(args) == 0
    assert "synthetic-8x6/blueprint" in capsys.readouterr().out
    assert json.loads((tmp_path / "sweep.json").read_text())["runs"][0]["seed"] == 3


def test_the_summary_is_the_mean_and_sample_spread_over_seeds():
    runs = [
        {"scene": "s", "seed": k, "rows": [{"dataset": "s/blueprint", "success_rate": v, "spl": v, "collisions": 0}]}
        for k, v in enumerate((0.5, 1.0))
    ]
    (entry,) = summarise(runs)
    assert entry["success_rate"]["mean"] == pytest.approx(0.75)
    assert entry["success_rate"]["std"] == pytest.approx(0.3535534, rel=1e-5)


@pytest.mark.parametrize(
    "bad", [dict(seeds=()), dict(preset="fast"), dict(threads=0), dict(ray_address="auto", executor="serial")]
)
def test_bad_sweep_settings_are_refused_before_anything_runs(bad):
    with pytest.raises(ConfigError):
        SweepConfig(**{**dict(scenes=("synthetic",)), **bad}).validate()
