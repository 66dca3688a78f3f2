"""A Ray cluster address where nothing listens fails in seconds with a typed error naming the address and how to fix
it, in ``build --executor ray`` (before anything is written) and in the RL sweep, instead of Ray's own retries
(which ran past 80 s); so does a port that answers but is no Ray cluster, after a bounded wait."""

import socket
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from dtradar_data.core.errors import InvalidSettingError, RayClusterError
from dtradar_data.core.ray_cluster import check_ray_address

ray = pytest.importorskip("ray")

FEW_SECONDS = 10.0


def within(seconds: float, fn):
    """``fn()``'s result or exception, in a thread: a call still running after ``seconds`` fails the test instead of
    hanging it (as ``ray.init`` did)."""
    box = {}

    def run():
        try:
            box["result"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still running after {seconds} s: it hangs"
    if "error" in box:
        raise box["error"]
    return box["result"]


@pytest.fixture
def dead_address(monkeypatch) -> str:
    """A loopback port where nothing listens (bound, then closed again); no ``$RAY_ADDRESS`` to override it."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"127.0.0.1:{port}"


def test_a_build_on_a_dead_ray_address_fails_in_seconds_and_writes_nothing(root, tmp_path, tiny_room, dead_address):
    from dtradar_data.cli import main

    room = tmp_path / "room.toml"
    room.write_text(tiny_room)
    args = ["build", "--scene", str(room), "--variant", "blueprint", "--no-coverage-map", "--no-progress"]
    assert within(FEW_SECONDS, lambda: main([*args, "--executor", "ray", "--ray-address", dead_address])) == 2
    assert not root.exists(), "a refused build wrote into the data root"


def test_the_error_names_the_address_and_how_to_fix_it(dead_address):
    with pytest.raises(RayClusterError) as err:
        check_ray_address(dead_address)
    assert dead_address in err.value.message and "nothing answers" in err.value.message
    assert "ray start --head" in err.value.hint and "drop --ray-address" in err.value.hint


def test_a_dead_ray_address_in_the_environment_is_named_as_such(dead_address, monkeypatch):
    monkeypatch.setenv("RAY_ADDRESS", dead_address)
    with pytest.raises(RayClusterError) as err:
        check_ray_address(None)
    assert f"$RAY_ADDRESS={dead_address}" in err.value.message and "unset RAY_ADDRESS" in err.value.hint


def test_an_address_without_a_port_is_refused(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    with pytest.raises(InvalidSettingError, match="no port"):
        check_ray_address("headnode")


def test_the_sweep_on_a_dead_ray_address_fails_in_seconds(tmp_path, dead_address):
    from dtradar_rl.experiments.sweep import SweepConfig, sweep

    if ray.is_initialized():  # a Ray left connected by another test would be reused, not connected to
        pytest.skip("Ray is already initialised in this process")
    cfg = SweepConfig(scenes=("synthetic-8x6",), seeds=(0,), ray_address=dead_address, out=str(tmp_path / "s"))
    with pytest.raises(RayClusterError, match=dead_address):
        within(FEW_SECONDS, lambda: sweep(cfg))
    assert not (tmp_path / "s").exists()


#: ray.init to a port that accepts connections but is no Ray cluster, bounded to 3 s, in its own process (Ray keeps
#: retrying in a background thread of the process that asked).
NOT_RAY = textwrap.dedent("""
    import socket, sys, time
    from dtradar_data.core.errors import RayClusterError
    from dtradar_data.core.ray_cluster import connect_ray
    import ray

    listener = socket.create_server(("0.0.0.0", 0))
    port = listener.getsockname()[1]
    t0 = time.monotonic()
    try:
        connect_ray(ray, f"127.0.0.1:{port}", timeout_s=3)
    except RayClusterError as exc:
        print(f"refused after {time.monotonic() - t0:.1f} s: {exc.message}")
        sys.exit(0)
    sys.exit("connected to something that is no Ray cluster")
""")


@pytest.mark.slow  # waits out its bounded wait: seconds (make test-all)
def test_a_port_that_answers_but_is_no_ray_cluster_fails_after_the_bounded_wait():
    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-c", NOT_RAY], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "no Ray cluster accepted this driver within 3 s" in out.stdout
    assert "connecting to the Ray cluster at 127.0.0.1:" in out.stderr, "the wait said what it waited for"
    assert time.monotonic() - t0 < 30


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_a_ray_without_the_cpus_a_task_needs_fails_instead_of_waiting_for_ever(tmp_path, monkeypatch):
    """A trace worker needs one CPU, a sweep run --threads of them on one node: a Ray that has no such node would
    leave them pending for ever, silently (this Ray is started here, so no node will join: it fails at once)."""
    import numpy as np

    from dtradar_data.pipeline.executors import trace_on_ray
    from dtradar_data.rt.settings import RTSettings
    from dtradar_rl.experiments.sweep import SweepConfig, sweep

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    if ray.is_initialized():
        pytest.skip("Ray is already initialised in this process")
    ray.init(num_cpus=0, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        points, ix, iy = np.zeros((1, 3)), np.zeros(1, int), np.zeros(1, int)
        with pytest.raises(RayClusterError, match="no node with 1 CPU"):
            within(FEW_SECONDS, lambda: trace_on_ray(None, RTSettings(), points, ix, iy, tmp_path, [0], per_path=False))
        cfg = SweepConfig(scenes=("synthetic-8x6",), seeds=(0,), threads=3, out=str(tmp_path / "s"))
        with pytest.raises(RayClusterError, match=r"no node with 3 CPU\(s\) for one run \(--threads 3\)"):
            within(FEW_SECONDS, lambda: sweep(cfg))
    finally:
        ray.shutdown()
    assert not list(tmp_path.iterdir())


class FakeCluster:
    """The few calls of Ray the waits make: a cluster whose largest node has ``cpus[k]`` CPUs at the k-th look."""

    def __init__(self, cpus):
        self.cpus = list(cpus)

    def nodes(self):
        cpus = self.cpus.pop(0) if len(self.cpus) > 1 else self.cpus[0]
        return [{"Alive": True, "Resources": {"CPU": float(cpus)}}]


@pytest.mark.slow  # waits out its bounded wait: seconds (make test-all)
def test_a_cluster_at_an_address_gets_a_bounded_wait_for_nodes_that_says_so(capsys, monkeypatch):
    from dtradar_data.core import ray_cluster

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(ray_cluster, "NOTICE_EVERY_S", 0.5)
    with pytest.raises(RayClusterError, match="none joined within 1.5 s"):
        ray_cluster.wait_for_cpus(FakeCluster([0]), 1, what="a trace worker", address="10.9.9.9:6379", timeout_s=1.5)
    err = capsys.readouterr().err
    assert "waiting up to 1.5 s for the Ray cluster at 10.9.9.9:6379" in err and "Ctrl-C is safe" in err
    assert "still waiting" in err
    joins = FakeCluster([0, 0, 4])  # an autoscaler adds a node with 4 CPUs
    assert ray_cluster.wait_for_cpus(joins, 2, what="a run", address="10.9.9.9:6379", timeout_s=30) == 4
