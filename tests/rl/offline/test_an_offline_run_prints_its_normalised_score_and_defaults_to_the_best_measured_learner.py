"""``python -m dtradar_rl offline`` prints each twin's normalised score (0 random, 100 shortest-path expert, on the
run's own evaluation pairs) in its results table and results.json, and its default learner is the best the offline
benchmark measured (DiscreteBCQ with the memory window and OGBench's goal mix)."""

import json
import re

import pytest

from dtradar_rl.cli import main
from dtradar_rl.evaluation.evaluate import markdown_table
from dtradar_rl.evaluation.normalized import normalized, reference_scores
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.relabel import RelabelConfig
from dtradar_rl.task.twins import load_dataset

SMALL = "synthetic-12x8"


def test_the_default_learner_is_bcq_with_its_measured_senses_and_goal_mix(capsys):
    cfg = OfflineConfig()
    assert cfg.algorithm == "bcq"
    assert cfg.resolved_senses == "memory" and cfg.relabel_config() == RelabelConfig.parse("ogbench")
    with pytest.raises(SystemExit):
        main(["offline", "--help"])
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    assert "Default bcq, the best measured" in text and "(default: bcq)" in text


def test_the_results_table_puts_the_normalised_score_after_spl_when_rows_have_it():
    row = {"case": "a", "pairs": 10, "success_rate": 0.5, "spl": 0.25, "collisions": 0.0, "steps": 3.0}
    head = markdown_table([{**row, "normalized": 12.34}]).splitlines()[0]
    assert "| SPL | normalised score (0 random, 100 expert) | collisions/ep |" in head
    assert "12.3 |" in markdown_table([{**row, "normalized": 12.34}])
    assert "normalised" not in markdown_table([row])


def test_an_offline_run_prints_and_records_each_twins_normalised_score(root, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["offline", "--scene", SMALL, "--algorithm", "bc", "--transitions", "2000", "--num-envs", "16"]
    argv += ["--n-steps", "50", "--hidden", "16", "--pairs", "60", "--threads", "1", "--no-latency", "--no-shield"]
    assert main([*argv, "--out", str(out), "--no-verbose"]) == 0
    printed = capsys.readouterr().out
    assert "normalised score (0 random, 100 expert)" in printed.splitlines()[0]
    rows = json.loads((out / "results.json").read_text())["results"]
    assert {r["dataset"] for r in rows} == {f"{SMALL}/blueprint", f"{SMALL}/dynamic"}
    for r in rows:
        refs = reference_scores(load_dataset(r["dataset"]), pairs=60, seed=2024)
        assert r["normalized"] == pytest.approx(normalized(r["spl"], refs))
        assert f"{r['normalized']:.1f} |" in printed


def test_each_epochs_line_says_the_updates_done_of_the_total_the_rate_and_the_time_left(root, tmp_path, capsys):
    argv = ["offline", "--scene", SMALL, "--algorithm", "bc", "--transitions", "2000", "--num-envs", "16"]
    argv += ["--n-steps", "50", "--hidden", "16", "--pairs", "20", "--threads", "1", "--no-latency", "--no-shield"]
    assert main([*argv, "--out", str(tmp_path / "run")]) == 0
    printed = capsys.readouterr().out
    lines = re.findall(r"bc epoch (\d+)/(\d+) step (\d+)/50, \d+ updates/s, (\d+) s left", printed)
    assert lines and lines[-1][0] == lines[-1][1] and lines[-1][2:] == ("50", "0"), printed
