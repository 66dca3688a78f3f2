"""The sionna-rt releases the batch-independent path solver is written for, and the cheap check of the installed one.

:mod:`dtradar_data.rt.batch_independent_solver` subclasses Sionna's PathSolver and its candidate generator and copies
two of their methods from one release. On another release the copies may no longer fit what they override (names,
arguments, buffer layouts): a trace would then fail deep inside a JIT-compiled loop, or give other paths without a
word. So :class:`~dtradar_data.rt.tracer.RayTracer` calls :func:`check_patched_sionna_rt` before it loads anything
for the patched solver: the installed version comes from the package metadata (nothing is imported), and a release
the patch was not written for is a :class:`~dtradar_data.core.errors.RayTracerUnavailableError` naming the installed
and the supported versions and the fix.
"""

from __future__ import annotations

from importlib import metadata

from dtradar_data.core.errors import RayTracerUnavailableError

__all__ = ["PATCHED_SIONNA_RT_VERSIONS", "check_patched_sionna_rt", "installed_sionna_rt"]

SIONNA_RT_DIST = "sionna-rt"
#: The sionna-rt releases whose PathSolver the patched solver copies (its lines marked CHANGED apart); the last is
#: the one pyproject.toml pins. Porting the patch to another release means comparing the two overridden methods with
#: that release's and re-running tests/data/rt/test_batch_independence.py, then adding the release here.
PATCHED_SIONNA_RT_VERSIONS: tuple[str, ...] = ("2.2.0",)


def installed_sionna_rt() -> str | None:
    """The installed sionna-rt's version, from its package metadata; None when it is not installed."""
    try:
        return metadata.version(SIONNA_RT_DIST)
    except metadata.PackageNotFoundError:
        return None


def check_patched_sionna_rt() -> None:
    """Raise :class:`RayTracerUnavailableError` unless the installed sionna-rt is one the patched solver is written
    for. A missing sionna-rt passes: importing Sionna then says so, and how to install it."""
    installed = installed_sionna_rt()
    if installed is None or installed in PATCHED_SIONNA_RT_VERSIONS:
        return
    supported = " or ".join(PATCHED_SIONNA_RT_VERSIONS)
    raise RayTracerUnavailableError(
        f"sionna-rt {installed} is installed, but the batch-independent path solver "
        f"(dtradar_data/rt/batch_independent_solver.py) patches Sionna internals of sionna-rt {supported}",
        hint=f"pip install sionna-rt=={PATCHED_SIONNA_RT_VERSIONS[-1]} (the version pyproject.toml pins; `make setup` "
        "installs it), or trace with --rt.no-batch-independent (Sionna's own solver: a cell's paths then depend on "
        "the cells traced with it)",
    )
