"""The offline benchmark beside its own failures: one benchmark per results folder (a second is refused, naming the
first one's pid); an interrupted benchmark run again trains only the runs it had not finished, in this process or on
Ray, and leaves nothing of the interrupted run half written, its report marked partial; a Ray worker killed mid-run
is retried, and one killed every time fails the benchmark with a typed error naming the run, its half-written folder
removed."""

import dataclasses
import hashlib
import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from dtradar_rl.cli import main
from dtradar_rl.experiments import offline_jobs
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench
from dtradar_rl.experiments.offline_jobs import ROW_FILE, TrainingLostError, finished_row
from dtradar_rl.task.runs import held_out_folder

SCENE = "synthetic-8x6"
TINY = dict(scene=SCENE, behaviours=("random",), seeds=(0,), steps=400, n_steps=10, num_envs=8, pairs=8)
TINY.update(fqe=False, tabular=False, verbose=False)

#: ``python -m dtradar_rl offline-bench ...`` that stops once its folder is held, before it logs its datasets.
HOLDER = """
import sys
import time

from dtradar_rl.experiments import offline_bench


def paused(*args, **kwargs):
    print("midway", flush=True)  # the parent starts its own benchmark into the folder here
    time.sleep(120)


offline_bench.log_datasets = paused
from dtradar_rl.cli import main

sys.exit(main(sys.argv[1:]))
"""


def files(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.rglob("*") if p.is_file()
    }


@pytest.mark.slow  # a benchmark held in a worker process: seconds (make test-all)
def test_a_second_benchmark_into_a_results_folder_in_use_is_refused_naming_the_holders_pid(
    root, tmp_path, paused_process, capsys
):
    out = tmp_path / "bench"
    argv = ["offline-bench", "--scene", SCENE, "--behaviours", "random", "--algorithms", "bc", "--seeds", "0"]
    argv += ["--n-steps", "10", "--steps", "400", "--num-envs", "8", "--pairs", "8", "--no-fqe", "--no-tabular"]
    holder = paused_process(HOLDER, *argv, "--out", out)
    holder.wait_for("midway")
    before = files(out)
    assert main([*argv, "--out", str(out), "--no-verbose"]) == 2
    err = capsys.readouterr().err
    assert f"--out {out} is in use by pid {holder.pid}" in err and "Traceback" not in err
    assert f"which is running the offline benchmark of {SCENE}: a second benchmark" in err
    assert "how to fix: wait until that one ends (or stop it), or pick another --out" in err
    assert files(out) == before
    holder.kill()
    with held_out_folder(out, "checking", what="job"):  # a killed holder's folder is free at once
        pass


def interrupted(tmp_path, monkeypatch) -> tuple[Path, dict]:
    """A benchmark of bc and nfq whose nfq run is interrupted (Ctrl-C) after it wrote part of its folder."""
    out = tmp_path / "bench"
    real = offline_jobs.run_job

    def stops_at_nfq(job):
        if job.algorithm == "nfq":
            job.config.out_dir.mkdir(parents=True)
            (job.config.out_dir / "model.d3").write_bytes(b"half a model")
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(offline_jobs, "run_job", stops_at_nfq)
    with pytest.raises(KeyboardInterrupt):
        run_bench(OfflineBenchConfig(**TINY, algorithms=("bc", "nfq"), workers=1, out=str(out)))
    monkeypatch.setattr(offline_jobs, "run_job", real)
    runs = out / "runs" / "random"
    assert (runs / "bc" / "seed0" / ROW_FILE).is_file()
    assert not (runs / "nfq" / "seed0").exists(), "the interrupted run's half-written folder went with it"
    assert not (out / ".dtradar-writer.lock").exists()
    return out, files(runs / "bc" / "seed0")


def test_an_interrupted_benchmark_run_again_trains_only_the_runs_it_had_not_finished(root, tmp_path, monkeypatch):
    out, bc_files = interrupted(tmp_path, monkeypatch)
    ran = []
    real = offline_jobs.run_job
    monkeypatch.setattr(offline_jobs, "run_job", lambda job: ran.append(job) or real(job))
    result = run_bench(OfflineBenchConfig(**TINY, algorithms=("bc", "nfq"), workers=1, out=str(out)))
    assert [j.algorithm for j in ran] == ["nfq"], "the finished bc run was reused, not trained again"
    assert result["layout"]["reused"] == 1 and result["layout"]["jobs"] == 1
    assert [r["algorithm"] for r in result["runs"]] == ["bc", "nfq"]
    assert files(out / "runs" / "random" / "bc" / "seed0") == bc_files, "not a byte of the reused run changed"
    nfq = out / "runs" / "random" / "nfq" / "seed0"
    assert (nfq / "model.d3").read_bytes() != b"half a model" and (nfq / ROW_FILE).is_file()
    # a run is reused only as it was run: other settings train it again
    (job,) = ran
    assert finished_row(job) is not None
    assert finished_row(dataclasses.replace(job, config=dataclasses.replace(job.config, n_steps=11))) is None
    assert finished_row(dataclasses.replace(job, logged=job.logged + "0")) is None


def test_the_report_an_interrupted_benchmark_leaves_says_it_is_partial_and_the_finished_one_does_not(
    root, tmp_path, monkeypatch
):
    out, _ = interrupted(tmp_path, monkeypatch)
    partial = json.loads((out / "bench.json").read_text())
    assert (partial["complete"], partial["runs_done"], partial["runs_planned"]) == (False, 1, 2)
    first = (out / "bench.md").read_text().splitlines()[0]
    assert first.startswith("**Partial results: 1 of 2 runs finished.** The benchmark stopped")
    assert "run the same command again" in first
    run_bench(OfflineBenchConfig(**TINY, algorithms=("bc", "nfq"), workers=1, out=str(out)))
    final = json.loads((out / "bench.json").read_text())
    assert (final["complete"], final["runs_done"], final["runs_planned"]) == (True, 2, 2)
    assert "Partial" not in (out / "bench.md").read_text()


@pytest.mark.slow  # a Ray session: seconds (make test-all)
def test_an_interrupted_benchmark_run_again_on_ray_trains_only_the_runs_it_had_not_finished(
    root, tmp_path, monkeypatch
):
    out, bc_files = interrupted(tmp_path, monkeypatch)
    result = run_bench(OfflineBenchConfig(**TINY, algorithms=("bc", "nfq"), executor="ray", out=str(out)))
    assert result["layout"]["reused"] == 1 and result["layout"]["jobs"] == 1
    pids = {r["algorithm"]: r["pid"] for r in result["runs"]}
    assert pids["bc"] == os.getpid() and pids["nfq"] != os.getpid(), "only nfq ran, on a Ray worker"
    assert files(out / "runs" / "random" / "bc" / "seed0") == bc_files


# -- a Ray worker killed mid-run -----------------------------------------------------------------------------------


@pytest.fixture()
def one_cpu_ray(root):
    """A local Ray of one CPU (one training at a time), started once the test's data root is set."""
    if not Path("/proc/self/cmdline").is_file():
        pytest.skip("finds Ray's worker processes in /proc")
    import ray

    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield ray
    ray.shutdown()


def ray_job_pids() -> set[int]:
    """The processes running a benchmark training as a Ray task (Ray names a busy worker after its task)."""
    pids = set()
    for p in Path("/proc").iterdir():
        try:
            if p.name.isdigit() and (p / "cmdline").read_bytes().startswith(b"ray::_ray_job"):
                pids.add(int(p.name))
        except OSError:
            pass
    return pids


def kill_workers(folder: Path, times: int, stop: threading.Event) -> list[int]:
    """In a thread: SIGKILL the worker running the training once its run folder exists (it has begun writing), up to
    ``times`` workers; returns the list of killed pids (filled as it goes)."""
    killed: list[int] = []

    def watch():
        while not stop.is_set() and len(killed) < times:
            if folder.exists():
                for pid in ray_job_pids() - set(killed):
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
            time.sleep(0.005)

    threading.Thread(target=watch, daemon=True).start()
    return killed


@pytest.mark.slow  # a Ray session and a worker started again: seconds (make test-all)
def test_a_ray_worker_killed_mid_run_is_retried_and_its_run_folder_holds_the_retry_alone(one_cpu_ray, tmp_path):
    out = tmp_path / "bench"
    folder = out / "runs" / "random" / "bc" / "seed0"
    stop = threading.Event()
    killed = kill_workers(folder, 1, stop)
    try:
        result = run_bench(OfflineBenchConfig(**TINY, algorithms=("bc",), executor="ray", out=str(out)))
    finally:
        stop.set()
    assert len(killed) == 1 and result["runs"][0]["pid"] != killed[0], "the run was trained again by another worker"
    assert len(result["runs"]) == 1 and result["layout"]["executor"] == "ray"
    names = sorted(files(folder))
    assert not [n for n in names if n.startswith(".")], f"no temporary file of the killed attempt: {names}"
    assert {"model.d3", "config.json", "losses.csv", ROW_FILE} <= set(names)


@pytest.mark.slow  # a Ray session and three workers started: seconds (make test-all)
def test_a_run_whose_ray_worker_is_killed_every_time_fails_the_benchmark_naming_it_and_leaves_no_half_run(
    one_cpu_ray, tmp_path
):
    out = tmp_path / "bench"
    folder = out / "runs" / "random" / "bc" / "seed0"
    stop = threading.Event()
    killed = kill_workers(folder, offline_jobs.RAY_RETRIES + 1, stop)
    try:
        with pytest.raises(TrainingLostError) as err:
            run_bench(OfflineBenchConfig(**TINY, algorithms=("bc",), executor="ray", out=str(out)))
    finally:
        stop.set()
    assert len(killed) == offline_jobs.RAY_RETRIES + 1
    message = str(err.value)
    assert f"the training bc on random (seed 0, {SCENE}/blueprint/random@" in message
    assert (
        "lost its Ray worker 3 times" in message and "run the benchmark again: it reuses the finished runs" in message
    )
    assert files(out) == {}, "no half-written run folder, no lock file"


def pool_worker_pids() -> set[int]:
    """This process's spawned worker processes (``multiprocessing``'s spawn start method)."""
    pids = set()
    for p in Path("/proc").iterdir():
        try:
            if p.name.isdigit() and b"multiprocessing.spawn" in (p / "cmdline").read_bytes():
                if int((p / "stat").read_text().rsplit(")", 1)[1].split()[1]) == os.getpid():
                    pids.add(int(p.name))
        except (OSError, ValueError, IndexError):
            pass
    return pids


@pytest.mark.slow  # two spawned worker processes: seconds (make test-all)
def test_a_worker_process_killed_mid_run_fails_the_benchmark_with_a_typed_error_and_no_half_run(root, tmp_path):
    if not Path("/proc/self/stat").is_file():
        pytest.skip("finds the worker processes in /proc")
    out = tmp_path / "bench"
    runs = out / "runs" / "random"
    stop, killed = threading.Event(), []

    def watch():
        while not stop.is_set() and not killed:
            if any(runs.glob("*/seed0")):  # a training has begun writing its folder
                for pid in pool_worker_pids():
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
            time.sleep(0.005)

    threading.Thread(target=watch, daemon=True).start()
    try:
        with pytest.raises(TrainingLostError, match="a training process died while the benchmark ran") as err:
            run_bench(OfflineBenchConfig(**TINY, algorithms=("bc", "nfq"), workers=2, out=str(out)))
    finally:
        stop.set()
    assert killed and "how to fix: run the benchmark again" in str(err.value)
    for folder in runs.glob("*/seed0"):  # a run that finished before the kill is kept, with its row
        assert (folder / ROW_FILE).is_file(), sorted(files(folder))
