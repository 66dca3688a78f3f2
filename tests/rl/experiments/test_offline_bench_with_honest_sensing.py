"""The offline benchmark with an honest sensing: honest logs, learners on the filter's belief, the tables followed
through the filter (no ceiling), the radio-filter agent as the online reference, and the sensing named in the
report."""

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
    tab = saved["tabular"]["expert"]
    assert set(tab) >= {"ce-filter", "lcb-filter", "spibb-filter"} and "ceiling" not in tab and "ce" not in tab
    assert all(0 <= tab[c][v]["spl"] <= 1 for c in ("ce-filter", "lcb-filter", "spibb-filter") for v in cfg.variants)
    assert "radio-filter" in saved["online_dqn"]["label"] and "blueprint" in saved["online_dqn"]
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "Sensing: **radio**, honest" in md and "| data ceiling |" not in md and "| CE + filter |" in md


def test_an_honest_benchmark_has_its_own_default_folder():
    assert str(OfflineBenchConfig(scene="cubicle", sensing="radio").out_dir) == "results/offline_bench/cubicle-radio"
    assert str(OfflineBenchConfig(scene="cubicle").out_dir) == "results/offline_bench/cubicle"
