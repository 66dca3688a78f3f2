"""The cache of exact solutions: ``<data root>/tabular/<scene>/<variant>/<version>/<reward>-gamma<γ>/``.

A solution (:class:`~dtradar_rl.tabular.solver.Solution`) is derived data, never part of a dataset: it is keyed by
the twin's content version, the reward and the discount, and solved again whenever what is stored cannot be trusted.
Its arrays (``values.npy``, ``q.npy``, ``targets.npy``, ``cells.npy``) are each written atomically, then
``solution.json`` with the size and sha256 of every array's file: the folder is complete once that JSON is there, and
a load re-hashes every file against it, so a damaged, short or unreadable file is noticed (:func:`check`), solved
again and rewritten, with one line naming the file (:func:`solve_twin`). A cache written before the hashes were
recorded has none to check against, and is solved again once, saying so.

One process writes a cache folder at a time: a writer holds the folder's lock (``.lock``, a
:func:`~dtradar_data.core.files.waiting_lock`: a second process that would solve the same twin, reward and discount
says whom it waits for, then reads what the first one stored). Every temp file beside a cache file while that lock is
held is therefore a killed writer's (a ``kill -9`` mid-write leaves its ``.q.npy.<random>.tmp``, as large as Q*), and
the holder removes it, saying so; a sound cache found beside such debris has it removed when the lock is free.

A read-only data root (a shared mirror, a container image) serves what is cached there; what is not (or cannot be
used) is solved for this run only, saying so, and nothing is written there.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from filelock import FileLock, Timeout

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import human_size, open_atomic, sha256_file, temp_siblings, waiting_lock
from dtradar_data.core.layout import data_root
from dtradar_data.store.logged import table_digest
from dtradar_rl.tabular.memory import chunk_size
from dtradar_rl.tabular.solver import FORMAT, GAMMA, Solution, TabularMDP, check_gamma, solve
from dtradar_rl.task.rewards import check_reward

__all__ = ["ARRAYS", "LOCK", "cache_dir", "check", "load", "remove_stale_temps", "save", "solve_twin"]

#: The arrays of a cached solution, each with its size and sha256 in ``solution.json``.
ARRAYS = ("values.npy", "q.npy", "targets.npy", "cells.npy")
META = "solution.json"
#: The lock a writer of a cache folder holds (inside it) while it solves and writes.
LOCK = ".lock"


def cache_dir(ds: Dataset, reward: str, gamma: float) -> Path:
    """``<data root>/tabular/<scene>/<variant>/<version>/<reward>-gamma<γ>/`` (derived data, never in the dataset)."""
    version = ds.version or f"table-{table_digest(ds.table)[:16]}"  # a synthetic twin: its content
    return data_root() / "tabular" / ds.name / version / f"{reward}-gamma{gamma:g}"


class _Hashed:
    """A binary file that hashes and counts what is written through it (``np.save`` writes a non-file object in
    chunks, so nothing is held twice)."""

    def __init__(self, f):
        self.f, self.sha, self.size = f, hashlib.sha256(), 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        self.sha.update(view)
        self.size += view.nbytes
        return self.f.write(view)

    def record(self) -> dict[str, object]:
        return {"bytes": self.size, "sha256": self.sha.hexdigest()}


def save(sol: Solution, folder: Path) -> Path:
    """``values.npy`` (V*, float64), ``q.npy`` (Q*, float32, ``K x N x 4``), ``targets.npy``, ``cells.npy`` and
    ``solution.json`` (with each array file's size and sha256), each written atomically; the JSON last, so a folder
    with it is complete. Q* is written chunk by chunk of targets: whole, it would take twice the memory of V* (and its
    list of chunks as much again)."""
    folder.mkdir(parents=True, exist_ok=True)
    k, n_t = chunk_size(sol.tab.n), sol.targets.size
    files = {}
    with open_atomic(folder / "q.npy", "wb") as f:
        out = _Hashed(f)
        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(np.float32)), "fortran_order": False}
        np.lib.format.write_array_header_1_0(out, {**header, "shape": (n_t, sol.tab.n, 4)})
        for i in range(0, n_t, k):
            out.write(np.ascontiguousarray(sol.q(np.arange(i, min(i + k, n_t))), np.float32))
        files["q.npy"] = out.record()
    for fname, arr in (("values.npy", sol.values), ("targets.npy", sol.targets), ("cells.npy", sol.tab.cells)):
        with open_atomic(folder / fname, "wb") as f:
            out = _Hashed(f)
            np.save(out, arr)
            files[fname] = out.record()
    with open_atomic(folder / META, "w") as f:
        f.write(json.dumps({**sol.meta(), "files": files}, indent=2) + "\n")
    return folder


def _damage(folder: Path, meta: dict) -> str:
    """Why the array files of ``folder`` do not match ``meta``'s sizes and hashes (naming the file), or ``""``."""
    files = meta.get("files")
    if not isinstance(files, dict) or not all(isinstance(files.get(n), dict) for n in ARRAYS):
        return f"{folder / META} has no content hashes (written before they were recorded)"
    for name in ARRAYS:
        path, want = folder / name, files[name]
        try:
            size = path.stat().st_size
            if size != want.get("bytes"):
                return f"{path} has {size:,} bytes, not the {want.get('bytes'):,} it was written with"
            if sha256_file(path) != want.get("sha256"):
                return f"{path} does not match its content hash (damaged)"
        except FileNotFoundError:
            return f"{path} is missing"
        except OSError as e:
            return f"{path} is unreadable ({e.strerror or e})"
    return ""


def check(folder: Path, tab: TabularMDP) -> tuple[Solution | None, str]:
    """``(the solution stored in folder for tab's twin, "")``, or ``(None, why)`` when it cannot be used: ``why`` is
    ``""`` when nothing is stored there, else one line naming the file that is missing, short, damaged or
    unreadable (or the other grid it was solved on)."""
    path = folder / META
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        left = [n for n in ARRAYS if (folder / n).exists()]
        return None, f"{path} is missing beside {', '.join(left)} (a solve that did not finish)" if left else ""
    except (OSError, ValueError) as e:
        return None, f"{path} is unreadable ({getattr(e, 'strerror', None) or e})"
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        return None, f"{path} is not a {FORMAT} solution"
    why = _damage(folder, meta)
    if why:
        return None, why
    try:
        cells = np.load(folder / "cells.npy")
        if not np.array_equal(cells, tab.cells):
            return None, f"{folder / 'cells.npy'} is of another grid than {tab.mdp.name}'s ({cells.size} cells)"
        values = np.load(folder / "values.npy")
        targets = np.load(folder / "targets.npy")
        if values.shape != (targets.size, tab.n):
            return None, f"{folder / 'values.npy'} has shape {values.shape}, not ({targets.size}, {tab.n})"
        return Solution(
            meta["dataset"], meta["version"], meta["reward"], float(meta["gamma"]), targets, values,
            int(meta["sweeps"]), float(meta["residual"]), float(meta["seconds"]), tab,
        ), ""  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError) as e:
        return None, f"the cached solution in {folder} is unreadable ({e})"


def load(folder: Path, tab: TabularMDP) -> Solution | None:
    """The solution stored in ``folder`` for ``tab``'s twin, or None when absent, incomplete, damaged (its files'
    sizes and hashes differ from those recorded) or for another grid (:func:`check` says which)."""
    return check(folder, tab)[0]


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def remove_stale_temps(folder: Path, say: Callable[[str], None] = _stderr) -> list[Path]:
    """Remove the temp files beside the cache files of ``folder`` (killed writers'), saying so; returns them. Call it
    only while holding the folder's :data:`LOCK`: every writer holds it while it writes, so none of them is live."""
    gone, size = [], 0
    for name in (*ARRAYS, META):
        for tmp in temp_siblings(folder / name):
            try:
                n = tmp.stat().st_size
                tmp.unlink()
            except OSError:  # gone meanwhile, or in a folder this process may not write: left as it is
                continue
            gone.append(tmp)
            size += n
    if gone:
        files = ", ".join(p.name for p in gone)
        say(f"removed what a killed solve left in {folder}: {files} ({human_size(size)})")
    return gone


def _tidy_if_free(folder: Path, say: Callable[[str], None]) -> None:
    """Beside a sound cache: remove killed writers' temp files when the folder's lock is free (no live writer), now."""
    if not any(temp_siblings(folder / name) for name in (*ARRAYS, META)) or not os.access(folder, os.W_OK | os.X_OK):
        return  # nothing to remove, or nothing this process may remove (filelock takes a read-only lock file too)
    lock = FileLock(str(folder / LOCK))
    try:
        lock.acquire(timeout=0)
    except (Timeout, OSError):  # a live writer's, or a folder this process may not write: left as it is
        return
    try:
        remove_stale_temps(folder, say)
    finally:
        lock.release()


def solve_twin(
    ds: Dataset,
    reward: str = "geodesic",
    gamma: float = GAMMA,
    *,
    cache: bool = True,
    progress=None,
    say: Callable[[str], None] = _stderr,
):
    """``(solution, cache folder, from the cache)`` of ``ds`` for every free cell as target: from the cache when
    stored and sound, else solved and stored, holding the folder's lock (module docstring). A stored solution that
    cannot be used is solved again and rewritten; ``say`` (default: stderr) gets one line naming its file, and one
    for the temp files of killed writers that are removed."""
    tab = TabularMDP.from_dataset(ds)
    gamma = check_gamma(gamma)
    folder = cache_dir(ds, check_reward(reward), gamma)
    if not cache:
        return _solve(ds, tab, reward, gamma, progress), folder, False
    sol, why = check(folder, tab)
    if sol is not None:
        _tidy_if_free(folder, say)
        return sol, folder, True
    read_only = _read_only(folder)
    if read_only:  # a shared mirror, a container image: solved for this run only
        if why:
            say(f"the cached solution cannot be used: {why}; solving it again")
        say(f"{read_only} is read-only: solving without caching (the solution is not stored)")
        return _solve(ds, tab, reward, gamma, progress), folder, False
    doing = f"solving {ds.name} exactly ({reward}, γ {gamma:g})"
    with waiting_lock(folder / LOCK, doing, then="read its solution from the cache", notice_after_s=2.0):
        sol, why = check(folder, tab)  # again: a writer we waited for has stored it meanwhile
        if sol is not None:
            remove_stale_temps(folder, say)
            return sol, folder, True
        if why:
            say(f"the cached solution cannot be used: {why}; solving it again")
        remove_stale_temps(folder, say)
        sol = _solve(ds, tab, reward, gamma, progress)
        save(sol, folder)
    return sol, folder, False


def _read_only(folder: Path) -> str:
    """The folder (``folder`` or the first one above it that had to be made) where the cache cannot be written, or
    ``""`` where it can."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        if e.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
            raise
        return str(Path(e.filename).parent) if e.filename else str(folder)
    return "" if os.access(folder, os.W_OK | os.X_OK) else str(folder)


def _solve(ds: Dataset, tab: TabularMDP, reward: str, gamma: float, progress) -> Solution:
    return solve(tab, reward, gamma, name=ds.name, version=ds.version or "", progress=progress)
