"""`make paper` on tiny synthetic tables: every table and figure of the report is written, missing twins are named."""

import json

from dtradar_rl.cli import main
from dtradar_rl.experiments.paper import PaperConfig, cross_groups


def test_a_tiny_paper_run_on_synthetic_tables_writes_every_file_of_the_report(tmp_path, root, capsys):
    out = tmp_path / "paper"
    status = main(
        [
            "paper",
            "--scenes",
            "synthetic-8x6",
            "dallas-q2",
            "--cross-scenes",
            "synthetic-8x6",
            "synthetic-6x6",
            "--episodes",
            "2",
            "--cross-steps",
            "600",
            "--cross-pairs",
            "4",
            "--threads",
            "1",
            "--out",
            str(out),
        ]
    )
    assert status == 0
    figs = {p.name for p in (out / "figures").iterdir()}
    assert figs == {
        "coverage_synthetic-8x6_blueprint.png",
        "coverage_synthetic-8x6_dynamic.png",
        "training_synthetic-8x6.png",
        "paths_synthetic-8x6_blueprint.png",
        "paths_synthetic-8x6_dynamic.png",
        "cross_custom_bars.png",
        "cross_custom_success.png",
        "cross_custom_spl.png",
    }
    md = (out / "report.md").read_text()
    for heading in (
        "Table II",
        "Table V",
        "Figs. 5 and 7",
        "Table VI",
        "Figs. 9, 11-16, 18-21",
        "Figs. 10, 22-24",
        "Table VII",
        "Fig. 17",
    ):
        assert heading in md
    for png in figs:
        assert f"figures/{png}" in md
    assert "make dataset SCENE=dallas-q2" in md  # the empty data root has no Dallas: named, and skipped
    assert "46 min" in md and "600,000" in md  # the paper's Table VII beside ours
    report = json.loads((out / "report.json").read_text())
    assert report["missing"][0]["dataset"] == "dallas-q2/blueprint"
    assert report["training"][0]["episodes"] == 2
    assert "[paper" in capsys.readouterr().out  # progress while it runs


def test_the_cross_quadrant_figure_groups_the_built_quadrants_of_each_city():
    twins = {f"dallas-q{k}/blueprint": None for k in (1, 3, 4)} | {"houston-q2/blueprint": None}
    cfg = PaperConfig(scenes=("cubicle", "dallas-q1", "dallas-q2", "dallas-q3", "dallas-q4", "houston-q2"))
    assert cross_groups(cfg, twins) == [("dallas", ["dallas-q1", "dallas-q3", "dallas-q4"])]


def test_the_report_calls_the_machine_shared_only_when_other_jobs_competed():
    from dtradar_rl.experiments.paper_report import shared_machine

    assert not shared_machine({"cores": 2, "load_avg_start": 0.08, "load_avg_max": 2.0})  # the run's own 2 threads
    assert shared_machine({"cores": 2, "load_avg_start": 0.3, "load_avg_max": 6.5})  # helpers training alongside
    assert shared_machine({"cores": 2, "load_avg_start": 1.9, "load_avg_max": 2.0})  # busy before it started
