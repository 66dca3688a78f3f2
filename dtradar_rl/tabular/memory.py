"""What the arrays of a tabular job take, checked against the memory this machine has before any is allocated.

A tabular problem's size is known before it starts: ``N`` states (free cells), ``K`` targets, 4 moves. What each job
holds at its peak was measured with ``tracemalloc`` (a synthetic 60 x 40 twin, two chunks of targets):

- the exact solution (:func:`~dtradar_rl.tabular.solver.solve`): V*, ``float64[K, N]``, and one chunk of targets'
  working arrays (rewards, the reached mask, their action-major copies, the Bellman gather), 7.5 ``float64[k, N, 4]``
  arrays, ``k`` the chunk's targets (:func:`chunk_size`); its greedy table (``solve``'s report) another
  ``int64[K, N]``; the cache's Q* is written chunk by chunk, never whole;
- the exact evaluation of a table policy (:func:`~dtradar_rl.tabular.evaluation.policy_values`): its values and 8.5
  chunk arrays;
- an online learner's table (:mod:`~dtradar_rl.tabular.qlearning`): ``float32[C, C, 4]`` over the grid's ``C``
  cells, then its greedy moves, an ``int64[C, C]``.

:data:`CHUNK_ARRAYS` covers the chunk arrays of all of them. A job whose estimate is above what the system reports
available (``MemAvailable``; not checked where the system does not say) is refused with :class:`TooLargeError`
naming each part, what is available and what makes it smaller: it would otherwise be killed by the OOM killer (or
swap for hours) after minutes of work, with nothing written.
"""

from __future__ import annotations

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.machine import available_memory

#: Working memory of one chunk of targets (its reward and value-gather arrays, float64 ``K x N x 4`` each).
CHUNK_BYTES = 64 << 20
#: The ``float64[k, N, 4]`` arrays one chunk of targets holds at once, at most (measured: 7.5 solving, 8.5
#: evaluating a table, 5.9 taking the greedy moves; module docstring).
CHUNK_ARRAYS = 9


class TooLargeError(InvalidSettingError):
    """A tabular problem (a solution, an evaluation, a learner's table) whose arrays would not fit the memory cap,
    or the memory this machine has, refused before anything is allocated; the message names the size."""


def chunk_size(n: int) -> int:
    """Targets per chunk so that one chunk's ``K x N x 4`` float64 arrays stay near :data:`CHUNK_BYTES`."""
    return max(1, min(n, CHUNK_BYTES // max(1, n * 4 * 8)))


def gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.2f} GiB"


def chunk_work(targets: int, states: int) -> int:
    """Bytes of one chunk of ``targets`` over ``states``' working arrays (:data:`CHUNK_ARRAYS`)."""
    return CHUNK_ARRAYS * min(int(targets), chunk_size(states)) * int(states) * 4 * 8


def solve_parts(targets: int, states: int, *, greedy: bool = False) -> dict[str, int]:
    """``{what: bytes}`` of an exact solution of ``targets`` x ``states`` (and of its greedy table)."""
    k, n = int(targets), int(states)
    parts = {f"V* (float64, {k:,} targets x {n:,} cells)": 8 * k * n}
    if greedy:
        parts[f"its greedy moves (int64, {k:,} x {n:,})"] = 8 * k * n
    parts[f"one chunk of {min(k, chunk_size(n)):,} targets' working arrays"] = chunk_work(k, n)
    return parts


def table_parts(cells: int, targets: int) -> dict[str, int]:
    """``{what: bytes}`` of an online learner's ``float32[cells, targets, 4]`` table and its greedy moves."""
    c, t = int(cells), int(targets)
    return {
        f"the Q table (float32, {c:,} cells x {t:,} targets x 4)": 16 * c * t,
        f"its greedy moves (int64, {c:,} x {t:,})": 8 * c * t,
    }


def check_memory(what: str, parts: dict[str, int], hint: str) -> int:
    """The bytes ``parts`` add up to, or :class:`TooLargeError` when they are more than this machine has available
    (``hint``: how to make ``what`` smaller)."""
    need = sum(parts.values())
    have = available_memory()
    if have is not None and need > have:
        listed = ", ".join(f"{name} {gib(size)}" for name, size in parts.items())
        raise TooLargeError(
            f"{what} needs about {gib(need)} of memory ({listed}); this machine has {gib(have)} available",
            hint=f"{hint}; or free memory (other processes) and run it again",
        )
    return need


__all__ = [
    "CHUNK_ARRAYS",
    "CHUNK_BYTES",
    "TooLargeError",
    "check_memory",
    "chunk_size",
    "chunk_work",
    "solve_parts",
    "table_parts",
]
