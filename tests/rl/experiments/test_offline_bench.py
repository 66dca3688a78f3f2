"""The offline-RL benchmark end to end in a reduced setting: logged datasets, d3rlpy runs over seeds, mean ± std,
JSON, Markdown and a bar plot; FQE beside the true value; the same runs in worker processes as in one."""

import json
import math

import pytest

from dtradar_rl.cli import main
from dtradar_rl.evaluation.normalized import normalized, reference_scores
from dtradar_rl.experiments import offline_jobs
from dtradar_rl.experiments.offline_bench import (
    BenchJob,
    OfflineBenchConfig,
    auto_workers,
    parallel_gain,
    run_bench,
    run_jobs,
)
from dtradar_rl.experiments.offline_report import aggregate, markdown, spearman
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset


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
        workers=1,
        fqe=False,
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
    # the tabular rows: the data's ceiling on the blueprint, the three learners on both twins, exact return scores
    tab = saved["tabular"]["random"]
    assert 0 <= tab["ceiling"]["blueprint"]["spl"] <= 1 and "return_normalized" in tab["ceiling"]["blueprint"]
    names = ("ce", "lcb", "spibb", "ce-senses", "lcb-senses")
    assert all(isinstance(tab[n][v]["normalized"], float) for n in names for v in cfg.variants)
    assert all(tab[n][v]["replans"] >= 0 for n in ("ce-senses", "lcb-senses") for v in cfg.variants)
    assert "data ceiling" in md and "| CE |" in md and "Π_b-SPIBB" in md and "return-based" in md
    assert "CE + senses" in md and "goals relabelled: auto" in md
    # --no-fqe: no off-policy evaluation anywhere
    assert "ope" not in saved and not any("fqe" in r for r in saved["runs"]) and "FQE" not in md
    assert not (tmp_path / "bench" / "bench_fqe.png").exists()


def test_without_the_deep_learners_the_benchmark_writes_the_tabular_rows_alone(root, tmp_path):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6",
        behaviours=("random",),
        deep=False,
        steps=400,
        num_envs=8,
        pairs=8,
        out=str(tmp_path / "bench"),
        verbose=False,
    )
    result = run_bench(cfg)
    assert result["runs"] == [] and result["algorithms"] == {} and "ope" not in result
    assert result["tabular"]["random"]["ce-senses"]["dynamic"]["success_rate"] >= 0
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "CE + senses" in md and "DiscreteCQL" not in md
    assert (tmp_path / "bench" / "bench.png").is_file()


def test_every_run_is_scored_on_the_normalised_scale_of_its_twin(root, tmp_path):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6",
        behaviours=("random", "expert"),
        algorithms=("bc",),
        seeds=(0,),
        steps=800,
        n_steps=10,
        num_envs=8,
        pairs=16,
        workers=1,
        fqe=False,
        out=str(tmp_path / "bench"),
        verbose=False,
    )
    result = run_bench(cfg)
    for v in ("blueprint", "dynamic"):
        refs = reference_scores(load_dataset(f"synthetic-8x6/{v}"), pairs=16, seed=2024)
        assert result["references"][v] == refs and refs["expert"] > refs["random"]
        for r in result["runs"]:
            assert r[v]["normalized"] == pytest.approx(normalized(r[v]["spl"], refs))
        # the behaviour itself on the same scale: the noisy shortest-path expert near 100, random near 0
        expert, rand = result["datasets"]["expert"]["eval"][v], result["datasets"]["random"]["eval"][v]
        assert expert["normalized"] > 60 > 30 > rand["normalized"]
    assert result["datasets"]["expert"]["logged_score"] > 60
    assert result["summary"][0]["blueprint"]["normalized"]["n"] == 1
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "**synthetic-8x6 → dynamic** (normalised score)" in md and "| expert |" in md


def test_the_score_table_has_a_row_per_dataset_and_the_best_algorithm_in_bold():
    from dtradar_rl.experiments.offline_report import score_table

    def entry(beh, algo, score):
        return {"behaviour": beh, "algorithm": algo, "blueprint": {"normalized": aggregate([score, score + 2])}}

    result = {
        "algorithms": {"bc": "DiscreteBC", "cql": "DiscreteCQL"},
        "datasets": {"expert": {"eval": {"blueprint": {"normalized": 94.5}}}, "medium-replay": {"eval": {}}},
        "summary": [entry("expert", "bc", 97.0), entry("expert", "cql", 80.0), entry("medium-replay", "cql", 40.0)],
    }
    lines = score_table(result, "blueprint")
    assert lines[0] == "| dataset | behaviour itself | DiscreteBC | DiscreteCQL |"
    assert lines[2] == "| expert | 94.5 | **98.0 ± 1.0** | 81.0 ± 1.0 |"
    assert lines[3] == "| medium-replay | - | - | **41.0 ± 1.0** |"


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_with_fqe_every_agent_gets_an_estimate_and_a_true_value_and_their_rank_correlation(root, tmp_path):
    cfg = OfflineBenchConfig(
        scene="synthetic-8x6",
        behaviours=("random", "noisy-shortest"),
        algorithms=("bc", "dqn"),
        seeds=(0,),
        steps=400,
        n_steps=20,
        fqe_steps=20,
        num_envs=8,
        pairs=8,
        workers=1,
        variants=("blueprint",),
        out=str(tmp_path / "bench"),
        verbose=False,
    )
    result = run_bench(cfg)
    saved = json.loads((tmp_path / "bench" / "bench.json").read_text())
    assert len(saved["runs"]) == 4
    assert all(math.isfinite(r["fqe"]) and math.isfinite(r["true_value"]) and r["fqe_s"] > 0 for r in saved["runs"])
    assert all(e["fqe"]["n"] == 1 and "true_value" in e for e in saved["summary"])
    ope = saved["ope"]
    assert ope["n"] == 4 and ope["gamma"] == 0.9 and ope["fqe_steps"] == 20
    assert ope["spearman"] == spearman([r["fqe"] for r in result["runs"]], [r["true_value"] for r in result["runs"]])
    md = (tmp_path / "bench" / "bench.md").read_text()
    assert "| FQE | true value |" in md and "Spearman rank correlation" in md
    assert (tmp_path / "bench" / "bench_fqe.png").stat().st_size > 1000


def test_spearman_is_the_rank_correlation_and_none_when_undefined():
    assert spearman([1, 2, 3, 4], [10, 20, 30, 40]) == 1.0
    assert spearman([1, 2, 3, 4], [4, 3, 2, 1]) == -1.0
    assert spearman([1, 2, 3, 4], [1, 3, 2, 4]) == pytest.approx(0.8)  # 1 - 6 * (0 + 1 + 1 + 0) / (4 * 15)
    assert spearman([1, 2], [1, 2]) is None and spearman([1, 1, 1], [1, 2, 3]) is None


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_two_worker_processes_train_the_same_agents_as_one_process(root, tmp_path):
    twin = load_dataset("synthetic-8x6/blueprint")
    logged = log_dataset(
        LogConfig(scene="synthetic-8x6", behaviour="random", steps=400, num_envs=8, minari=False, verbose=False), twin
    )
    jobs = [
        BenchJob(
            behaviour="random",
            algorithm=algo,
            seed=1,
            logged=f"{logged.name}@{logged.version}",
            config=OfflineConfig(
                scene="synthetic-8x6",
                algorithm=algo,
                seed=1,
                n_steps=20,
                batch_size=32,
                hidden=(16,),
                pairs=8,
                eval_variants=("blueprint",),
                shield=False,
                verbose=False,
                out=str(tmp_path / layout / algo),
            ),
        )
        for layout in ("one", "two")
        for algo in ("dqn", "bc")
    ]
    one = run_jobs(jobs[:2], workers=1)
    two = run_jobs(jobs[2:], workers=2)
    key = lambda r: r["algorithm"]
    pids = {r["pid"] for r in two}
    assert len(pids) >= 1 and all(r["pid"] != one[0]["pid"] for r in two)  # they ran in other processes
    for a, b in zip(sorted(one, key=key), sorted(two, key=key)):
        assert a["blueprint"] == b["blueprint"] and a["final_losses"] == b["final_losses"], (a, b)


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_the_benchmark_on_ray_gives_the_same_table_as_in_one_process(root, tmp_path):
    base = dict(scene="synthetic-8x6", behaviours=("random",), algorithms=("bc", "dqn"), seeds=(0, 1), steps=400)
    base.update(n_steps=10, num_envs=8, pairs=8, fqe=False, verbose=False)  # the tables beside the trainings on Ray
    serial = run_bench(OfflineBenchConfig(**base, workers=1, out=str(tmp_path / "serial")))
    on_ray = run_bench(OfflineBenchConfig(**base, executor="ray", out=str(tmp_path / "ray")))
    assert on_ray["layout"]["executor"] == "ray" and len(on_ray["runs"]) == 4
    senses = lambda r: {
        v: r["tabular"]["random"]["ce-senses"][v] for v in base.get("variants", ("blueprint", "dynamic"))
    }  # noqa: E731
    assert senses(on_ray) == senses(serial)  # the tables' scores (not their seconds) wherever they ran
    scores = lambda r: [{k: v for k, v in e.items() if k != "train_s"} for e in r["summary"]]  # noqa: E731
    assert scores(on_ray) == scores(serial)
    # the quotable tables (one row per twin here), not the per-run metrics with their training seconds
    table = lambda r: [line for line in markdown(r).splitlines() if line.startswith("| random | ")][:2]  # noqa: E731
    assert table(on_ray) == table(serial)


def test_ray_settings_without_the_ray_executor_are_refused():
    with pytest.raises(ConfigError, match="--ray-address applies to --executor ray"):
        OfflineBenchConfig(ray_address="auto").validate()
    with pytest.raises(ConfigError, match="--workers applies"):
        OfflineBenchConfig(executor="ray", workers=2).validate()


def test_the_benchmark_command_refuses_an_unknown_algorithm(root, capsys):
    assert main(["offline-bench", "--scene", "synthetic-8x6", "--algorithms", "cqll"]) == 2
    assert "did you mean 'cql'" in capsys.readouterr().err


def test_trainings_run_side_by_side_only_when_the_cores_measurably_work_in_parallel(monkeypatch):
    assert parallel_gain(1, seconds=0.05) > 0
    monkeypatch.setattr(offline_jobs.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(offline_jobs, "parallel_gain", lambda k: 1.1)  # the cores busy with other jobs
    assert auto_workers(90) == (1, 1.1)
    monkeypatch.setattr(offline_jobs, "parallel_gain", lambda k: 1.6)
    assert auto_workers(90) == (2, 1.6) and auto_workers(1) == (1, None)
