"""The offline benchmark's line per finished training says which run of how many it was and about how long the
others will take (the finished trainings' pace), so a quarter-hour benchmark is not opaque."""

import re

import pytest

from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_each_finished_run_says_its_count_of_the_total_and_the_time_left(root, tmp_path, capsys):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6", behaviours=("random",), algorithms=("bc", "nfq"), seeds=(0,), steps=400, n_steps=10,
        num_envs=8, pairs=8, fqe=False, tabular=False, workers=1, out=str(tmp_path / "bench"),
    )  # fmt: skip
    run_bench(cfg)
    lines = re.findall(r"run (\d)/(\d), about (\d+\.\d) min left: random", capsys.readouterr().out)
    assert [(a, b) for a, b, _ in lines] == [("1", "2"), ("2", "2")]
    assert lines[-1][2] == "0.0"
