"""Will a build fit? A cheap check of memory and disk before any ray is traced, where the need can be predicted.

Tracing holds one batch at a time, so memory is bounded by the batch, not by the city: Sionna allocates its
candidate-path buffer (``max_num_paths_per_src``) per trace, which dominates. Measured on this machine: about 2.1-2.3
GB resident with a 10^7 buffer (the cubicle at 10^6 samples, Dallas at 10^5), 0.8 GB with 10^6 (Munich). Disk: the
work folder of finished batches and the stored Parquet files grow with the free cells and their paths (measured:
the cubicle's per-path table is 3.1 KB per free cell indoors; outdoor cells hold more paths). The estimates are
deliberately generous: the check refuses only builds that cannot fit.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from dtradar_data.core.errors import DtradarError
from dtradar_data.core.machine import available_memory  # here too: a build's check, patched in tests
from dtradar_data.rt.settings import RTSettings

BASE_BYTES = 600 * 2**20  # interpreter, Dr.Jit/Mitsuba, the scene
BYTES_PER_BUFFERED_PATH = 200  # ~2 GB at a 1e7 buffer
BYTES_PER_CELL = 2_000  # a batch's receivers: arrays over cells x paths beyond the buffer
DISK_BYTES_PER_FREE_CELL = 40_000  # work folder + Parquet with the per-path table, outdoor (a ~10x margin indoors)


class InsufficientResourcesError(DtradarError, MemoryError):
    """The build would run out of memory or disk; nothing was traced."""


def estimate_memory(settings: RTSettings, transmitters: int = 1) -> int:
    """Bytes one trace holds: the candidate-path buffer is per source, so it grows with the transmitters."""
    buffered = BYTES_PER_BUFFERED_PATH * settings.max_num_paths_per_src * transmitters
    return BASE_BYTES + buffered + BYTES_PER_CELL * settings.batch_size


def check_resources(
    name: str, free_cells: int, settings: RTSettings, work_dir: Path, *, per_path: bool, transmitters: int = 1
) -> None:
    """Raise :class:`InsufficientResourcesError` when the build cannot fit in this machine's memory or disk."""
    need = estimate_memory(settings, transmitters)
    have = available_memory()
    if have is not None and need > have:
        raise InsufficientResourcesError(
            f"{name}: tracing needs about {need / 2**30:.1f} GiB of memory (a path buffer of "
            f"{settings.max_num_paths_per_src:.0e} paths per transmitter, {transmitters} transmitter(s), batches of "
            f"{settings.batch_size} cells); "
            f"{have / 2**30:.1f} GiB are available",
            hint="lower --rt.max-num-paths-per-src (fewer weak paths kept) or --rt.batch-size, use fewer "
            "transmitters, or free memory",
        )
    disk_need = free_cells * transmitters * (DISK_BYTES_PER_FREE_CELL if per_path else DISK_BYTES_PER_FREE_CELL // 20)
    probe = next(p for p in (work_dir, *work_dir.parents) if p.exists())
    disk_have = shutil.disk_usage(probe).free
    if disk_need > disk_have:
        raise InsufficientResourcesError(
            f"{name}: {free_cells} free cells need about {disk_need / 2**20:.0f} MiB of disk in {probe}; "
            f"{disk_have / 2**20:.0f} MiB are free",
            hint="free disk space, point DTRADAR_DATA_ROOT at a larger disk, use --no-per-path, or coarser cells",
        )
