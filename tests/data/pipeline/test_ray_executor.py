"""Trace batches on Ray: the same table as a serial build, a clear error without Ray, and a worker killed with
SIGKILL mid-build is replaced and its batch retried (real Ray, real ray tracer, a 6 x 4 corner of the cubicle)."""

import os
import signal
import subprocess
import threading
import time
from dataclasses import replace

import pytest

from dtradar_data.core.layout import work_root
from dtradar_data.pipeline import tracing
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.inputs import build_inputs
from dtradar_data.pipeline.static_build import build_one
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store.versions import version_id

pytestmark = pytest.mark.sionna
ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


@pytest.fixture
def small_cubicle():
    spec = load_scene_spec("cubicle", "blueprint")
    return replace(spec, grid=replace(spec.grid, nx=6, ny=4))


def config(samples: int = 2_000):
    return BuildConfig(
        scene="cubicle",
        coverage_map=False,
        progress=False,
        rt=RTSettings(max_depth=1, samples_per_src=samples, batch_size=5, device="cpu"),
    )


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_a_ray_build_stores_the_same_table_and_version_as_a_serial_build(root, monkeypatch, small_cubicle, local_ray):
    serial = build_one(small_cubicle, config())
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(root.parent / "ray-root"))
    on_ray = build_one(small_cubicle, replace(config(), executor="ray", workers=2))
    assert on_ray.version == serial.version
    assert on_ray.table.equals(serial.table)


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_a_worker_killed_mid_build_is_replaced_and_the_build_finishes_unchanged(root, small_cubicle, local_ray):
    cfg = replace(config(samples=40_000), executor="ray", workers=2)
    spec_cfg = scene_config(cfg, small_cubicle)
    work = work_root() / "cubicle" / "blueprint" / version_id(build_inputs(small_cubicle, spec_cfg))
    killed = []

    def kill_one_worker():
        deadline = time.monotonic() + 300  # Ray workers start slowly on a busy machine
        while time.monotonic() < deadline and not killed:
            done = list(work.rglob("batch_*.npz")) if work.is_dir() else []
            pids = subprocess.run(["pgrep", "-f", "ray::TraceWorker"], capture_output=True, text=True).stdout.split()
            if done and len(done) < 4 and pids:
                os.kill(int(pids[0]), signal.SIGKILL)
                killed.append(int(pids[0]))
            time.sleep(0.05)

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    on_ray = build_one(small_cubicle, cfg)
    killer.join()
    assert killed, "no worker was running mid-build to kill"
    serial = tracing.trace_grid(small_cubicle, spec_cfg.rt, None, progress=False)[0]
    assert on_ray.table.equals(serial)


def test_asking_for_ray_without_ray_installed_names_the_install_command(monkeypatch):
    import builtins

    from dtradar_data.core.errors import MissingDependencyError

    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray":
            raise ImportError("No module named 'ray'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    with pytest.raises(MissingDependencyError, match=r"dtradar\[ray\]"):
        BuildConfig(scene="cubicle", executor="ray")


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_a_ray_session_keeps_its_workers_warm_from_one_scene_to_the_next(small_cubicle, local_ray, tmp_path):
    from dtradar_data.pipeline.executors import RaySession

    settings = replace(config().rt, batch_size=8)
    meeting = load_scene_spec("meeting", "blueprint")
    meeting = replace(meeting, grid=replace(meeting.grid, nx=5, ny=4))
    with RaySession(workers=2) as session:
        first = tracing.trace_grid(small_cubicle, settings, tmp_path / "a", progress=False, executor="ray")[0]
        pids = sorted(ray.get([a.pid.remote() for a in session.actors]))
        second = tracing.trace_grid(meeting, settings, tmp_path / "b", progress=False, executor="ray")[0]
        assert sorted(ray.get([a.pid.remote() for a in session.actors])) == pids, "the same workers, not new ones"
    assert ray.is_initialized(), "a Ray the caller started stays up"
    assert first.equals(tracing.trace_grid(small_cubicle, settings, None, progress=False)[0])
    assert second.equals(tracing.trace_grid(meeting, settings, None, progress=False)[0])
