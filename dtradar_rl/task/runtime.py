"""The machine a job runs on: its description for every report and benchmark, and how many CPU threads a small
torch network should use on it right now."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import torch

from dtradar_data.core.machine import describe
from dtradar_data.core.machine import machine as _host


def machine() -> dict[str, Any]:
    """:func:`dtradar_data.core.machine.machine` (CPU, cores, load, memory, platform, Python) plus what torch sees:
    ``gpu`` (the first CUDA device's name, or None), ``torch`` and ``torch_threads``. The one description every
    report and benchmark of dtradar_rl records; :func:`describe` turns it into one line."""
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {**_host(), "gpu": gpu, "torch": torch.__version__, "torch_threads": torch.get_num_threads()}


def idle_cores(interval_s: float = 0.25) -> float:
    """Cores left idle by other processes right now (from ``/proc/stat`` over ``interval_s``; Linux), else from
    the 1-minute load average."""

    def snapshot():
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        return v[3] + v[4], sum(v)  # idle + iowait, total

    cores = os.cpu_count() or 1
    try:
        (i0, t0), _ = snapshot(), time.sleep(interval_s)
        i1, t1 = snapshot()
        return cores * (i1 - i0) / max(1, t1 - t0)
    except (OSError, ValueError, IndexError):
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
        return max(0.0, cores - load)


def auto_threads(max_threads: int = 2) -> int:
    """Torch threads for small networks: ``max_threads`` on an idle machine, fewer when other processes keep cores
    busy. Measured on 2 cores: with another busy process, 2 torch threads collapse to ~5 % of the 1-thread speed
    (the threads wait on each other), while on an idle machine 2 threads are ~1.5x faster than 1.
    """
    return max(1, min(max_threads, int(round(idle_cores()))))


#: Torch threads for one robot's decision (batch 1). Measured with ``make bench-latency`` on 2 cores: with two
#: intra-op threads the same forward pass takes 0.06 ms in some runs and 8-16 ms in others (the threads wait on
#: each other whenever another process holds a core); with one thread it stays near 0.06 ms, idle or not.
DECISION_THREADS = 1


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads, then restore the previous count."""
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


__all__ = ["DECISION_THREADS", "auto_threads", "describe", "idle_cores", "machine", "torch_threads"]
