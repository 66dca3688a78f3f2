"""A benchmark's training processes leave with it: a killed benchmark leaves no worker training on."""

import os
import signal
import subprocess
import sys
import time

import pytest

#: a pool of two benchmark workers, each busy with a long job, the workers' pids printed
POOL = """
import os, time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from dtradar_rl.experiments.offline_jobs import _init_worker
with ProcessPoolExecutor(2, mp_context=get_context("spawn"), initializer=_init_worker) as pool:
    pids = set()
    while len(pids) < 2:
        pids |= {f.result() for f in [pool.submit(os.getpid) for _ in range(8)]}
    jobs = [pool.submit(time.sleep, 120) for _ in range(4)]
    print(" ".join(map(str, sorted(pids))), flush=True)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has exited
    except FileNotFoundError:
        return False


@pytest.mark.slow  # spawns worker processes: seconds (make test-all)
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_workers_of_a_benchmark_killed_by_sigkill_exit_instead_of_training_on():
    proc = subprocess.Popen([sys.executable, "-c", POOL], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(_alive(p) for p in pids)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 15
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_alive(p) for p in pids)
    finally:
        proc.kill()
