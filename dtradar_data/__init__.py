"""dtradar_data: Sionna RT digital-twin datasets, one row per grid cell, stored as versioned Parquet.

    >>> import dtradar_data
    >>> ds = dtradar_data.load("cubicle/blueprint")     # newest version in the data root
    >>> ds.frame, ds.table, ds.grid(), ds.blocked, ds.meta
"""

from __future__ import annotations

from . import llvm as _llvm
from .dataset import Dataset, GridInfo
from .errors import DtradarError, RayTracerUnavailableError

# Point Dr.Jit at a libLLVM >= 16 now, before anything imports mitsuba/drjit (they read it once, at import).
# An explicit DRJIT_LIBLLVM_PATH wins; with none found, the ray tracer raises a typed error when first used.
try:
    _llvm.configure()
except RayTracerUnavailableError:
    pass

__all__ = ["Dataset", "GridInfo", "DtradarError", "load", "list_datasets"]


def __getattr__(name: str):
    # Loading lives in .store; imported lazily so `import dtradar_data` stays cheap and never touches Sionna.
    if name in ("load", "list_datasets"):
        from . import store

        return getattr(store, name)
    raise AttributeError(f"module 'dtradar_data' has no attribute {name!r}")
