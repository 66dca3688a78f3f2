"""Scene → meshes → Sionna RT over the grid → per-cell table → versioned Parquet in the data root.

``build(BuildConfig(scene="cubicle"))`` builds both static variants (:mod:`.static_build`); ``variant="moving"``
builds the moving twin instead (:mod:`.moving_build`: snapshot 0 in full, each later snapshot differentially from
the one before). The version of a dataset is the hash of its inputs (:mod:`.inputs`: scene description, RT
settings, schema version, library versions), computed before any tracing: building the same thing twice reuses the
stored version (:mod:`.storing`). Tracing runs in receiver batches (:mod:`.tracing`); each finished batch is kept
under ``<data root>/work/`` so an interrupted build continues where it stopped, on the device it traced on
(:mod:`.resume`), and the work folder is removed once the version is stored. The flags and their checks:
:mod:`.config`.
"""

from __future__ import annotations

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.ids import MOVING_VARIANT
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.moving_build import build_moving
from dtradar_data.pipeline.static_build import build_static
from dtradar_data.store.writing import clean_stages

__all__ = ["build", "build_moving", "build_static"]


def build(config: BuildConfig) -> list[Dataset]:
    """Build the requested variant(s) of ``config.scene``; returns the stored datasets. Everything that can refuse
    the build is checked before the first variant is traced (:func:`build_static`, :func:`build_moving`), after the
    staging folders of killed builds and pulls are removed (their disk then counts as free; a resumable build's own
    work folder is kept)."""
    clean_stages()
    if config.variant == MOVING_VARIANT:
        return build_moving(config)
    return build_static(config)
