"""The store step every build ends with, static or moving: one build of a version at a time (a lock), reuse of a
version already stored, the metadata every version records, the atomic write, and the work folder's cleanup.

A build hands :func:`store_version` its dataset id, its version (the hash of its inputs, known before tracing) and
a ``make`` step that traces and returns the :class:`NewVersion` to write; ``make`` runs only when the version is not
stored yet, with the lock held.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import pyarrow as pa

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import waiting_lock
from dtradar_data.core.ids import DatasetId, format_id
from dtradar_data.core.layout import PICTURE_FILES, work_root
from dtradar_data.core.schema import SCHEMA_VERSION
from dtradar_data.pipeline.resume import claim_device
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import active_variant
from dtradar_data.store import local, writing

REDUCTION_DOC = (
    "path power = |a|^2 averaged over all (RX port, TX port) pairs; strongest path = largest path power; "
    "a_re/a_im/phase_rad = coefficient of the strongest path at RX port 0 / TX port 0 (first element, first "
    "polarisation); path_gain_db = 10 log10 of the sum of path powers; delay_spread_s = power-weighted RMS delay spread"
)


@dataclass(frozen=True)
class NewVersion:
    """A traced version, ready to write: its tables, its ``meta.json``, the files stored beside them (drawn into
    the temporary folder :func:`store_version` hands ``make``), and the tracer to close once it is written."""

    cells: pa.Table
    paths: pa.Table | None
    meta: dict
    extra_files: dict[str, Path]
    tracer: Any = None


#: ``make(work_dir, tmp) -> NewVersion``: trace (resumable in ``work_dir``) and draw the extra files into ``tmp``.
Make = Callable[[Path, Path], NewVersion]


def store_version(
    ds_id: DatasetId,
    version: str,
    make: Make,
    *,
    progress: Callable[[Path], str],
    how: str = "",
    rt: RTSettings | None = None,
) -> Dataset:
    """Build (or reuse) ``version`` of ``ds_id``: the stored one if it exists, else ``make``'s, written atomically;
    returns it loaded. ``progress(work_dir)`` says how far this build has come to another process waiting for it;
    ``how`` (" (differential)") is added to what that one is told this build does. With ``rt``, the device it traces
    on is claimed in the work folder first (:func:`~dtradar_data.pipeline.resume.claim_device`: a partial build of
    the other device is refused)."""
    local.check_can_store(ds_id, version)  # a damaged version folder would otherwise fail only after tracing
    name = format_id(ds_id)
    work_dir = work_root() / ds_id.scene / ds_id.variant / version
    work_dir.parent.mkdir(parents=True, exist_ok=True)
    # One build of a version at a time: a second process waits here, then finds the version built and reuses it
    # (without the lock, the first one's cleanup deleted the shared work folder under the second). The wait says
    # whom it waits for, and how far that build has come, on stderr.
    with waiting_lock(
        work_dir.parent / f"{version}.lock",
        f"building {name} version {version}{how}",
        then="this build reuses that version",
        progress=lambda: progress(work_dir),
    ):
        if local.version_exists(ds_id, version):
            print(f"{name}: version {version} already built, reusing it")
            ds = local.load(name, revision=version)
            say_pictures(name, ds.path)
            return ds
        return write_new_version(ds_id, version, work_dir, make, rt)


def say_pictures(name: str, version_dir: Path) -> None:
    """Print where the version's pictures are (the radio map, the table's own, a city's overview, a moving twin's
    animation), so a build's user opens them without knowing the store's layout."""
    for picture in PICTURE_FILES:
        if (version_dir / picture).is_file():
            print(f"{name}: picture {version_dir / picture}")


def write_new_version(
    ds_id: DatasetId, version: str, work_dir: Path, make: Make, rt: RTSettings | None = None
) -> Dataset:
    """The lock held and the version not stored: claim the device (with ``rt``), ``make`` it, write it, then remove
    the work folder (its batches are kept until the version is stored, so a failed build's retry does not trace
    again, on the device it traced on)."""
    name = format_id(ds_id)
    if rt is not None:
        claim_device(work_dir, rt, name)
    with tempfile.TemporaryDirectory(prefix="dtradar-build-") as tmp:
        new = make(work_dir, Path(tmp))
        out = writing.write_version(ds_id, version, new.cells, new.meta, paths=new.paths, extra_files=new.extra_files)
    if new.tracer is not None:
        new.tracer.close()
    shutil.rmtree(work_dir, ignore_errors=True)
    print(f"{name}: stored version {version} in {out}")
    say_pictures(name, out)
    return local.load(name, revision=version)


def version_meta(spec, settings: RTSettings, name: str, version: str, inputs: dict) -> dict:
    """The metadata every built version records about its scene, settings and libraries."""
    return {
        "name": name,
        "scene": spec.scene,
        "variant": spec.variant,
        "version": version,
        "schema_version": SCHEMA_VERSION,
        "title": spec.title,
        "description": spec.description,
        "scene_spec": spec.to_dict(),
        "scene_hash": spec.digest(),
        "rt": {
            **settings.hashed(),
            "reduction": REDUCTION_DOC,
            "solver": "sionna.rt.PathSolver",
            "mitsuba_variant": active_variant() or "(reused cached batches)",
        },
        "transmitter": spec.tx.to_dict(),
        **({"transmitters": [t.to_dict() for t in spec.transmitters]} if spec.more_tx else {}),
        "grid": spec.grid.to_dict(),
        "rx_height_m": spec.rx_height_m,
        "robot_height_m": spec.robot_height_m,
        "library_versions": inputs["library_versions"],
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "licence": spec.licence,
        "attribution": spec.attribution,
        "source": spec.source,
        **({"city": city} if (city := _provenance(spec)) else {}),
        **({"tx_pose_error": spec.provenance["tx_pose_error"]} if "tx_pose_error" in spec.provenance else {}),
    }


def _provenance(spec) -> dict:
    """What ``meta["city"]`` records: the scene's provenance without the pose error (recorded on its own)."""
    return {k: v for k, v in spec.provenance.items() if k != "tx_pose_error"}
