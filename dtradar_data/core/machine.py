"""What machine a measurement ran on: CPU model, cores, load averages, memory, platform, Python.

Benchmarks record :func:`machine` next to their timings and print :func:`describe` in their headings
(``"Intel(R) Xeon(R) CPU @ 2.20GHz, 2 cores, 7.8 GiB, load 1.3 / 1.1 / 0.9"``), so a number can be read against the
load it was measured under. Standard library only; anything the platform does not report is ``None``.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import Any

__all__ = ["available_memory", "machine", "describe"]

_CPUINFO_KEYS = ("model name", "Model", "Hardware", "Processor", "cpu model", "cpu")


def available_memory() -> int | None:
    """Bytes of memory available to a new process (``MemAvailable`` of ``/proc/meminfo``); None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cpu_model() -> str:
    """The CPU's marketing name from ``/proc/cpuinfo`` (Linux), else what :mod:`platform` says."""
    try:
        fields = {}
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            key, sep, value = line.partition(":")
            if sep and value.strip():
                fields.setdefault(key.strip(), value.strip())
        for key in _CPUINFO_KEYS:
            if key in fields:
                return fields[key]
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def _memory_bytes() -> int | None:
    """Total physical memory: ``MemTotal`` of ``/proc/meminfo``, else ``sysconf``; None when neither is there."""
    try:
        for line in Path("/proc/meminfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) * 1024  # the file counts kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return None


def machine() -> dict[str, Any]:
    """The machine now, JSON-ready: ``cpu``, ``arch``, ``cores`` (logical), ``usable_cores`` (this process may run
    on: fewer in a container or under ``taskset``), ``load_average`` (1, 5, 15 min), ``memory_bytes``, ``platform``,
    ``python``."""
    try:
        usable: int | None = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        usable = os.cpu_count()
    try:
        load: list[float] | None = [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        load = None
    return {
        "cpu": _cpu_model(),
        "arch": platform.machine(),
        "cores": os.cpu_count(),
        "usable_cores": usable,
        "load_average": load,
        "memory_bytes": _memory_bytes(),
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def describe(m: dict[str, Any] | None = None) -> str:
    """One line for a heading: ``"<cpu>, <n> cores, <memory> GiB, load <1> / <5> / <15>"`` of ``m`` (default: now)."""
    m = machine() if m is None else m
    cores, usable = m.get("cores"), m.get("usable_cores")
    parts = [m.get("cpu") or "unknown CPU"]
    if cores:
        parts.append(f"{usable} of {cores} cores" if usable and usable != cores else f"{cores} cores")
    if m.get("memory_bytes"):
        parts.append(f"{m['memory_bytes'] / 2**30:.1f} GiB")
    if m.get("load_average"):
        parts.append("load " + " / ".join(f"{x:.1f}" for x in m["load_average"]))
    return ", ".join(parts)
