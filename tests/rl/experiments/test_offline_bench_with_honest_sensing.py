"""The offline benchmark with an honest sensing: honest logs, learners on the filter's belief, no tabular rows, the
radio-filter agent as the online reference, and the sensing named in the report."""

import json

from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench


def test_an_honest_benchmark_logs_honest_data_and_says_so(root, tmp_path):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6",
        behaviours=("expert",),
        algorithms=("bc",),
        seeds=(0,),
        steps=200,
        n_steps=10,
        num_envs=8,
        pairs=8,
        workers=1,
        fqe=False,
        sensing="radio",
        out=str(tmp_path / "bench"),
        verbose=False,
    )
    result = run_bench(cfg)
    saved = json.loads((tmp_path / "bench" / "bench.json").read_text())
    assert saved["config"]["sensing"] == "radio" and saved["config"]["sensing_noise"] == "realistic"
    assert result["datasets"]["expert"]["name"] == "synthetic-8x6/blueprint/expert-radio"
    assert "tabular" not in saved or not saved["tabular"]  # the tables act on cells: not run with honest sensing
    assert "radio-filter" in saved["online_dqn"]["label"] and "blueprint" in saved["online_dqn"]
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "Sensing: **radio**, honest" in md and "data ceiling" not in md


def test_an_honest_benchmark_has_its_own_default_folder():
    assert str(OfflineBenchConfig(scene="cubicle", sensing="radio").out_dir) == "results/offline_bench/cubicle-radio"
    assert str(OfflineBenchConfig(scene="cubicle").out_dir) == "results/offline_bench/cubicle"
