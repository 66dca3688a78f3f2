"""Evaluation metrics on hand-made paths, greedy rollouts, the Markdown table and the CLI round trip."""

import json

import numpy as np
import pytest
import torch

from dtradar_data.core.errors import DtradarError
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.cli import main
from dtradar_rl.evaluation.evaluate import LATENCY_DECISIONS, decision_latency_ms, markdown_table, path_length, spl
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.twins import load_dataset


def test_spl_of_an_optimal_path_is_one():
    mdp = GridMDP.from_blocked(np.zeros((4, 5), bool))
    path = mdp.shortest_path(mdp.cell(0, 0), mdp.cell(4, 3))
    assert spl([True], [7], [path_length(path)]) == 1.0


def test_spl_of_a_detour_is_the_length_ratio_and_of_a_failure_zero():
    assert spl([True], [4], [8]) == pytest.approx(0.5)
    assert spl([False], [4], [4]) == 0.0
    assert spl([True, False], [4, 4], [4, 4]) == pytest.approx(0.5)


def test_collisions_do_not_lengthen_the_travelled_path():
    assert path_length([0, 1, 1, 1, 2]) == 2  # two collisions in between
    assert path_length([5]) == 0


def test_markdown_table_lists_every_case():
    md = markdown_table(
        [
            {
                "case": "a -> b",
                "sensing": "radio",
                "pairs": 3,
                "success_rate": 1.0,
                "spl": 0.9,
                "collisions": 0.0,
                "steps": 4.0,
                "shortest": 3.0,
                "latency_ms": None,
            }
        ]
    )
    assert md.splitlines()[0].startswith("| case | sensing | pairs | success | SPL")
    assert "| a -> b | radio | 3 | 1.000 | 0.900 | 0.00 | 4.0 | 3.0 | - | - |" in md
    assert "decision p50 (ms) | p99 (ms)" in md.splitlines()[0]


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_cli_trains_then_evaluates_on_blueprint_and_dynamic(tmp_path, capsys):
    run = tmp_path / "dqn"
    assert (
        main(
            [
                "train",
                "--scene",
                "synthetic-6x5",
                "--total-env-steps",
                "3000",
                "--num-envs",
                "16",
                "--hidden",
                "32",
                "32",
                "--learning-starts",
                "500",
                "--env-steps-per-update",
                "8",
                "--out",
                str(run),
                "--no-verbose",
                "--threads",
                "1",
            ]
        )
        == 0
    )
    assert (run / "model.pt").exists() and (run / "config.json").exists()
    out = tmp_path / "eval"
    assert (
        main(
            [
                "eval",
                "--scene",
                "synthetic-6x5",
                "--checkpoint",
                str(run / "model.pt"),
                "--pairs",
                "20",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "synthetic-6x5/blueprint -> synthetic-6x5/dynamic" in printed
    results = json.loads((out / "results.json").read_text())
    assert [(r["dataset"], r["shield"]) for r in results["results"]] == [
        ("synthetic-6x5/blueprint", False),
        ("synthetic-6x5/blueprint", True),
        ("synthetic-6x5/dynamic", False),
        ("synthetic-6x5/dynamic", True),
        ("synthetic-6x5/blueprint", False),
        ("synthetic-6x5/dynamic", False),
    ]  # + the classical baseline
    assert [r["case"].startswith("planner: ") for r in results["results"]] == [False] * 4 + [True] * 2
    for name in ("results.md", "config.json", "paths_blueprint.png", "paths_dynamic.png"):
        assert (out / name).exists(), name

    noisy = tmp_path / "eval-noise"
    argv = ["eval", "--scene", "synthetic-6x5", "--checkpoint", str(run / "model.pt"), "--pairs", "20"]
    assert main([*argv, "--noise", "2x", "--no-planner", "--out", str(noisy)]) == 0
    rows = json.loads((noisy / "results.json").read_text())["results"]
    assert [r["case"].endswith("noise 2x)") for r in rows] == [True] * 4
    assert {r["noise"] for r in rows} == {"2x"} and (noisy / "paths_dynamic_noise-2x.png").exists()
    assert {r["sensing"] for r in rows} == {"privileged"}  # a DQN's observation holds the robot's x, y
    assert main([*argv, "--noise", "loud"]) == 2
    assert "unknown noise level 'loud'" in capsys.readouterr().err


def test_cli_reports_a_missing_checkpoint_with_a_fix(tmp_path, capsys):
    assert main(["eval", "--scene", "synthetic-6x5", "--checkpoint", str(tmp_path / "none.pt")]) == 2
    assert "make train" in capsys.readouterr().err


def test_cross_matrix_over_a_list_of_datasets(tmp_path):
    for s in ("synthetic-6x5", "synthetic-7x5"):
        assert (
            main(
                [
                    "train",
                    "--preset",
                    "tuned",
                    "--scene",
                    s,
                    "--total-env-steps",
                    "1000",
                    "--num-envs",
                    "16",
                    "--hidden",
                    "16",
                    "--learning-starts",
                    "500",
                    "--out",
                    str(tmp_path / s),
                    "--no-verbose",
                    "--threads",
                    "1",
                ]
            )
            == 0
        )
    assert (
        main(
            [
                "cross",
                "--scenes",
                "synthetic-6x5",
                "synthetic-7x5",
                "--checkpoint-pattern",
                str(tmp_path / "{scene}" / "model.pt"),
                "--pairs",
                "10",
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 0
    )
    m = json.loads((tmp_path / "x" / "cross.json").read_text())["config"]["matrix"]
    assert np.array(m["success"]).shape == (2, 2)
    assert (tmp_path / "x" / "cross_success.png").exists()


def test_shield_never_moves_into_a_sensed_obstacle(tmp_path):
    assert (
        main(
            [
                "train",
                "--preset",
                "tuned",
                "--scene",
                "synthetic-6x5",
                "--total-env-steps",
                "1000",
                "--num-envs",
                "16",
                "--hidden",
                "16",
                "--learning-starts",
                "500",
                "--out",
                str(tmp_path),
                "--no-verbose",
                "--threads",
                "1",
            ]
        )
        == 0
    )
    from dtradar_rl.evaluation.evaluate import evaluate
    from dtradar_rl.task.twins import load_dataset
    from dtradar_rl.train.saved_runs import load_policy

    policy = load_policy(tmp_path / "model.pt")
    metrics, _ = evaluate(policy, load_dataset("synthetic-6x5/dynamic"), pairs=50, latency=False, shield=True)
    assert metrics.collisions == 0.0


def test_shield_needs_the_neighbors_preset(tmp_path):
    assert (
        main(
            [
                "train",
                "--preset",
                "tuned",
                "--scene",
                "synthetic-6x5",
                "--obs",
                "goal",
                "--total-env-steps",
                "600",
                "--num-envs",
                "16",
                "--hidden",
                "8",
                "--learning-starts",
                "500",
                "--out",
                str(tmp_path),
                "--no-verbose",
                "--threads",
                "1",
            ]
        )
        == 0
    )
    from dtradar_rl.train.saved_runs import load_policy

    with pytest.raises(DtradarError, match="neighbors"):
        load_policy(tmp_path / "model.pt").shield_columns()


def test_batch_1_decisions_are_timed_single_threaded_and_the_thread_count_is_restored():
    ds = load_dataset("synthetic-12x8/blueprint")
    planner = FingerprintPlanner(ds)
    seen = []
    act = planner.act

    def recording(obs, shield=False):
        seen.append((obs.shape[0], torch.get_num_threads()))
        return act(obs, shield)

    planner.act = recording
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        p50, p99 = decision_latency_ms(planner, ds, repeats=200)
        assert torch.get_num_threads() == 2  # restored
    finally:
        torch.set_num_threads(before)
    assert 0 < p50 <= p99
    assert len(seen) >= 200 and set(seen) == {(1, 1)}  # one robot, one thread, every decision
    assert LATENCY_DECISIONS >= 1000  # what evaluate() times by default
