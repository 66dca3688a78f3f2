"""The resume state of a partial build: the device it traces on, so that a resumed build never mixes two in a table.

A build keeps its finished work in ``<root>/work/<scene>/<variant>/<version>/`` (trace batches, a moving twin's
snapshots) until the version is stored, and the next build of the same version continues from it. The device is no
part of the version (:meth:`~dtradar_data.rt.settings.RTSettings.hashed` leaves it out, and the versions of the
committed cards must stay as they are), yet a CPU (LLVM) and a CUDA trace of Sionna's own solver need not be the same
bytes (other kernels, other summation orders), so a build resumed on the other device would store a table whose rows
come from two ray tracers under one version. ``resume.json`` in the work folder records the device the partial build
traces on (:func:`claim_device`, before anything is traced), and a resume on the other device is refused, saying
which device it used and how to go on. Batch-independent tracing, the default, traces on the CPU whatever
``--rt.device auto`` finds; the refusal matters for ``--rt.no-batch-independent --rt.device cuda`` against ``cpu``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.files import write_atomic
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import trace_device

__all__ = ["RESUME_FILE", "claim_device", "read_state", "traced_parts"]

RESUME_FILE = "resume.json"


def read_state(work_dir: Path) -> dict[str, Any]:
    """The resume state in ``work_dir`` (empty when there is none, or it is unreadable: then nothing is claimed)."""
    try:
        state = json.loads((Path(work_dir) / RESUME_FILE).read_text())
    except (OSError, ValueError):
        return {}
    return state if isinstance(state, dict) else {}


def traced_parts(work_dir: Path) -> int:
    """How many finished parts ``work_dir`` holds: trace batches (a static build's, a moving twin's snapshot 0) and a
    moving twin's snapshots."""
    work_dir = Path(work_dir)
    if not work_dir.is_dir():
        return 0
    return sum(1 for _ in work_dir.rglob("batch_*.npz")) + sum(1 for _ in work_dir.glob("snapshot_*.json"))


def claim_device(work_dir: Path, settings: RTSettings, name: str) -> str:
    """Record in ``work_dir`` the device this build traces on and return it; :class:`InvalidSettingError` when the
    partial build there traced on the other one. A record with no traced part beside it (a build that stopped before
    its first batch) is replaced: nothing of it would be mixed."""
    device = trace_device(settings)
    recorded = read_state(work_dir).get("device")
    parts = traced_parts(work_dir) if recorded and recorded != device else 0
    if parts:
        asked = f"--rt.device {settings.device}" + (f" (here: {device})" if settings.device == "auto" else "")
        raise InvalidSettingError(
            f"{asked}: the partial build of {name} in {work_dir} traced {parts} finished part(s) on the "
            f"{recorded.upper()}; resuming it on the {device.upper()} would store one table traced on both devices",
            hint=f"resume it on the same device (--rt.device {recorded}), or delete the partial build "
            f"(`rm -r {work_dir}`) and build again to trace it all on the {device.upper()}",
        )
    if recorded != device:
        Path(work_dir).mkdir(parents=True, exist_ok=True)
        write_atomic(Path(work_dir) / RESUME_FILE, json.dumps({"device": device}, sort_keys=True) + "\n")
    return device
