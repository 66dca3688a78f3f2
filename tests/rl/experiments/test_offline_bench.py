"""The offline-RL benchmark end to end in a reduced setting: logged datasets, d3rlpy runs over seeds, mean ± std,
JSON, Markdown and a bar plot."""

import json

from dtradar_rl.cli import main
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, aggregate, run_bench


def test_mean_and_std_are_over_seeds():
    assert aggregate([0.5, 1.0]) == {"mean": 0.75, "std": 0.25, "n": 2}


def test_a_tiny_benchmark_runs_end_to_end_in_seconds(root, tmp_path):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6",
        behaviours=("random",),
        algorithms=("bc", "nfq"),
        seeds=(0, 1),
        steps=400,
        n_steps=10,
        num_envs=8,
        pairs=8,
        out=str(tmp_path / "bench"),
        verbose=False,
    )
    result = run_bench(cfg)
    assert {(e["behaviour"], e["algorithm"]) for e in result["summary"]} == {
        (b, a) for b in cfg.behaviours for a in cfg.algorithms
    }
    assert all(e["blueprint"]["success_rate"]["n"] == 2 and "dynamic" in e for e in result["summary"])
    saved = json.loads((tmp_path / "bench" / "bench.json").read_text())
    assert len(saved["runs"]) == 4 and saved["machine"]["start"]["cores"] >= 1
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "DiscreteBC" in md and "NFQ" in md and " ± " in md and "behaviour itself" in md
    assert (tmp_path / "bench" / "bench.png").stat().st_size > 1000
    assert result["datasets"]["random"]["name"] == "synthetic-8x6/blueprint/random"


def test_the_benchmark_command_refuses_an_unknown_algorithm(root, capsys):
    assert main(["offline-bench", "--scene", "synthetic-8x6", "--algorithms", "cqll"]) == 2
    assert "did you mean 'cql'" in capsys.readouterr().err
