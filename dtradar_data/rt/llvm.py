"""Find a libLLVM >= 16 for Dr.Jit's CPU backend, before Mitsuba is imported.

Sionna RT on the CPU runs through Dr.Jit's LLVM backend. Debian 12's default LLVM 14/15 aborts with
"LLVM ERROR: Cannot select ... fmaximum", so we point ``DRJIT_LIBLLVM_PATH`` at a newer library. Order:

1. an explicit ``DRJIT_LIBLLVM_PATH`` (always wins, never second-guessed);
2. the ``karellen-llvm-core`` wheel installed by ``make setup`` (``<venv>/lib/libLLVM.so.*``);
3. a system LLVM 16+ (Debian ``libllvm16``..``libllvm23``: ``/usr/lib/llvm-N/lib/libLLVM*.so*``).

``make setup`` ends with ``python -m dtradar_data check``, which prints what was found and runs one JIT kernel, or
prints the install command when nothing was found.
"""

from __future__ import annotations

import glob
import os
import re
import sys
from pathlib import Path

from dtradar_data.core.errors import RayTracerUnavailableError

MIN_MAJOR = 16
ENV_VAR = "DRJIT_LIBLLVM_PATH"
INSTALL_HINT = (
    "install one: `pip install karellen-llvm-core` (no root; `make setup` does this), or "
    "`apt-get install libllvm19` on Debian/Ubuntu; or set DRJIT_LIBLLVM_PATH=/path/to/libLLVM.so (version >= 16)"
)


def _major(path: Path) -> int | None:
    for pattern in (r"libLLVM[-.]?(\d+)", r"llvm-(\d+)", r"\.so\.(\d+)"):
        m = re.search(pattern, str(path))
        if m:
            return int(m.group(1))
    return None


def candidates() -> list[Path]:
    """Every libLLVM >= 16 we know where to look for, best first."""
    found: list[Path] = []
    for prefix in dict.fromkeys([sys.prefix, sys.exec_prefix, sys.base_prefix]):
        found += sorted(Path(p) for p in glob.glob(os.path.join(prefix, "lib", "libLLVM.so.*")))
        found += sorted(Path(p) for p in glob.glob(os.path.join(prefix, "lib", "libLLVM-*.so")))
    system = glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*") + glob.glob("/usr/lib/*-linux-gnu/libLLVM-*.so*")
    found += sorted((Path(p) for p in system), key=lambda p: -(_major(p) or 0))
    return [p for p in found if p.is_file() and (_major(p) or 0) >= MIN_MAJOR]


def find_libllvm() -> Path:
    """The library Dr.Jit should load; raises :class:`RayTracerUnavailableError` when there is none."""
    explicit = os.environ.get(ENV_VAR)
    if explicit:
        if not Path(explicit).is_file():
            raise RayTracerUnavailableError(f"{ENV_VAR}={explicit} does not exist", hint=INSTALL_HINT)
        return Path(explicit)
    found = candidates()
    if not found:
        raise RayTracerUnavailableError(f"no libLLVM >= {MIN_MAJOR} found for Sionna RT on the CPU", hint=INSTALL_HINT)
    return found[0]


def configure() -> Path:
    """Set ``DRJIT_LIBLLVM_PATH`` (unless already set) and return the library in use. Idempotent."""
    path = find_libllvm()
    os.environ[ENV_VAR] = str(path)
    return path
