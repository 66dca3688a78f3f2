"""dtradar_data: Sionna RT digital-twin datasets, one row per grid cell, stored as versioned Parquet.

    >>> import dtradar_data
    >>> ds = dtradar_data.load("cubicle/blueprint")     # newest version in the data root
    >>> ds.frame, ds.table, ds.grid(), ds.blocked, ds.meta
    >>> logged = dtradar_data.load("cubicle/blueprint/noisy-shortest")   # a logged offline-RL dataset (LoggedDataset)

Layers, each importing only those below it (checked by import-linter in ``make test``)::

    cli                     the ``python -m dtradar_data`` commands
    publish | pipeline      Hub, committed cards, load-with-fallback | the resumable ray-tracing pipeline
    store   | rt            versions, local store, cards, listing    | LLVM discovery, Sionna tracer, path -> cell
    geometry                meshes, Mitsuba XML, occupancy, floor plans
    scenes                  the scene model, materials, scene files
    core                    ids, schema, Dataset, Grid, errors, data-root layout

The public surface, the only modules ``dtradar_rl`` (or any user code) needs and imports (checked by
``tests/test_architecture.py``): this package (``load``, ``list_datasets``, the synthetic twins, ...), every module of
:mod:`dtradar_data.core`, the store's two packages :mod:`dtradar_data.store` (RT datasets: resolve, meta, refs,
versions, staging folders) and :mod:`dtradar_data.store.logged` (logged datasets), :mod:`dtradar_data.scenes`,
:mod:`dtradar_data.rt.settings` (what a dataset's ``rt`` record means; no Sionna) and
:mod:`dtradar_data.geometry.floorplan` (a twin's floor plan under a plot). Everything else is the builder's own.
"""

from __future__ import annotations

from dtradar_data.core.dataset import Dataset, GridInfo
from dtradar_data.core.errors import DtradarError, RayTracerUnavailableError
from dtradar_data.pipeline.synthetic import synthetic_dataset, synthetic_moving_dataset
from dtradar_data.publish.loading import load
from dtradar_data.rt import llvm as _llvm
from dtradar_data.store.listing import list_datasets
from dtradar_data.store.logged import LoggedDataset, list_logged

# Point Dr.Jit at a libLLVM >= 16 now, before anything imports mitsuba/drjit (they read it once, at import).
# An explicit DRJIT_LIBLLVM_PATH wins; with none found, the ray tracer raises a typed error when first used.
try:
    _llvm.configure()
except RayTracerUnavailableError:
    pass

__all__ = [
    "Dataset",
    "GridInfo",
    "DtradarError",
    "LoggedDataset",
    "load",
    "list_datasets",
    "list_logged",
    "synthetic_dataset",
    "synthetic_moving_dataset",
]
