"""`make train` / `make eval` without flags: the default agent (honest sensing) beside the privileged DQN and the
planner, every row naming its sensing."""

import json

import pytest

from dtradar_rl.cli import main

TRAIN = ["--total-env-steps", "2000", "--num-envs", "16", "--hidden", "16", "--learning-starts", "500"]


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_eval_without_flags_reports_the_default_agent_the_privileged_dqn_and_the_planner(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["eval", "--scene", "synthetic-6x5", "--pairs", "10"]) == 2  # no agent built yet
    assert "make train SCENE=synthetic-6x5" in capsys.readouterr().err
    assert main(["agent", "--scene", "synthetic-6x5"]) == 0
    assert (tmp_path / "runs/synthetic-6x5/agent/agent.json").exists()
    assert main(["train", "--scene", "synthetic-6x5", *TRAIN, "--no-verbose", "--threads", "1"]) == 0
    assert main(["eval", "--scene", "synthetic-6x5", "--pairs", "10"]) == 0
    rows = json.loads((tmp_path / "runs/synthetic-6x5/eval/results.json").read_text())["results"]
    by_label = {(r["case"].split(":")[0], r["dataset"], r["shield"]): r["sensing"] for r in rows}
    assert by_label[("radio filter", "synthetic-6x5/blueprint", False)] == "radio"
    assert by_label[("privileged DQN", "synthetic-6x5/dynamic", True)] == "privileged"
    assert by_label[("planner", "synthetic-6x5/dynamic", False)] == "radio"
    assert {r["noise"] for r in rows} == {"realistic"}
    assert "| sensing |" in capsys.readouterr().out


def test_eval_can_observe_the_default_agent_with_another_honest_sensing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["agent", "--scene", "synthetic-6x5"]) == 0
    argv = ["eval", "--scene", "synthetic-6x5", "--pairs", "10", "--sensing", "no-radio", "--no-planner"]
    assert main(argv) == 0
    rows = json.loads((tmp_path / "runs/synthetic-6x5/eval/results.json").read_text())["results"]
    assert {r["sensing"] for r in rows} == {"no-radio"}
    assert main([*argv[:-3], "--sensing", "privileged"]) == 2


def test_a_twin_that_is_not_built_is_skipped_naming_its_build_command(root, capsys):
    from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent
    from dtradar_rl.evaluation.evaluate import evaluate_twins
    from dtradar_rl.task.twins import load_dataset

    agent = RadioFilterAgent(load_dataset("synthetic/blueprint"), FilterConfig(scene="synthetic"))
    assert evaluate_twins(agent, "cubicle", ["moving"], pairs=5, latency=False) == []
    out = capsys.readouterr().out
    assert "skipping cubicle/moving" in out and "how to fix:" in out and "VARIANT=moving" in out


def test_eval_names_under_its_table_a_twin_asked_for_but_not_built(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["agent", "--scene", "synthetic-6x5"]) == 0
    argv = ["eval", "--scene", "synthetic-6x5", "--pairs", "5", "--variants", "blueprint", "dynamic"]
    assert main([*argv, "--no-planner"]) == 0
    md = (tmp_path / "runs/synthetic-6x5/eval/results.md").read_text()
    assert "Not evaluated" not in md  # every twin asked for is there

    import json

    from dtradar_rl.evaluation.evaluate import write_results

    rows = json.loads((tmp_path / "runs/synthetic-6x5/eval/results.json").read_text())["results"]
    md = write_results(rows, tmp_path / "again", {}, missing=["cubicle/moving"])
    assert "Not evaluated (not built here): cubicle/moving" in md
    assert json.loads((tmp_path / "again/results.json").read_text())["not_evaluated"] == ["cubicle/moving"]
