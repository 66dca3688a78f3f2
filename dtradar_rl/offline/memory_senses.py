"""Offline agents with the online default's senses: every logged step observed as the memory agent would observe it.

The default online agent (``memory-escape-noise-margin``) sees its ``neighbors`` observation followed by a window of
what it has sensed and visited this episode and the count of its earlier stands on its cell
(:class:`~dtradar_rl.envs.memory.MemoryNavEnv`); a greedy policy that sees it can tell a dead end it already tried
and leaves a loop by a random move (``escape_after``). Everything in that window follows from the episode's own
cells and the has-radio flags it observed, none of it from the target, so a logged episode's memory observations
are rebuilt exactly from the log, for the logged target and for any relabelled goal alike (the memory of a path does
not depend on where the path was meant to go).

:class:`MemorySenses` holds them for a log (``uint8``, one row per step and one more per episode: the memory after
its last move) and extends d3rlpy's arrays and minibatches with them; :func:`memory_arrays` gives the log's d3rlpy
arrays with the window appended (the trainer's dataset and FQE's). The layout is the default preset's
(:data:`MEMORY_SETTINGS`: radius 5, the visit count, escape after 2 earlier stands, no bump map), and evaluation
runs in the same memory env on both twins (:class:`~dtradar_rl.agents.policy.Policy.env_for` reads the settings from
the run's config). Tested against :class:`~dtradar_rl.envs.memory.MemoryGymEnv` replaying the logged moves.
"""

from __future__ import annotations

import time

import numpy as np

from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.envs.memory import VISITS_CAP, MemoryLayout, flag_columns
from dtradar_rl.offline.config import MEMORY_SETTINGS
from dtradar_rl.offline.log_cache import LogCache, log_content
from dtradar_rl.task.grid_mdp import GridMDP

#: Episodes whose memory maps are replayed together (each holds ``maps x padded cells`` int16 values).
CHUNK = 512


class MemorySenses:
    """The memory window of every step of a log (module docstring).

    ``window[i]`` is what the robot's memory shows at step ``i`` (before its move), ``window[next_row[i]]`` after
    it: the next step's row inside an episode, an extra row after each episode's last step."""

    def __init__(self, logged: LoggedDataset, mdp: GridMDP, *, radius: int, bumps: bool = False, visits: bool = True):
        t0 = time.perf_counter()
        #: what the windows follow from (:func:`senses_content`): a d3rlpy dataset built with them is kept by it
        self.content = senses_content(logged, mdp, radius, bumps, visits)
        self.log = log_content(logged)  #: the sha256 of the transitions alone (a sampler checks its parts by it)
        self.layout = MemoryLayout(mdp.nx, mdp.ny, radius, bumps=bumps, visits=visits)
        a = logged.arrays()
        cell, action = a["cell"].astype(np.int64), a["action"].astype(np.int64)
        flags = flag_columns()
        # what the robot sensed around it: the has-radio flags of the observation it had on each cell
        occ_here = a["obs"][:, flags] < 0.5
        occ_next = a["next_obs"][:, flags] < 0.5
        nxt = mdp.next_cell[cell, action]
        collides = mdp.collides[cell, action]
        n = len(cell)
        ends = np.flatnonzero(a["terminated"] | a["truncated"])
        starts = np.r_[0, ends[:-1] + 1]
        self.window = np.zeros((n + len(ends), self.layout.dim), np.uint8)
        self.next_row = np.arange(1, n + 1, dtype=np.int64)
        self.next_row[ends] = n + np.arange(len(ends))
        for c in range(0, len(ends), CHUNK):
            self._replay(
                starts[c : c + CHUNK], ends[c : c + CHUNK], n + c, cell, action, nxt, collides, occ_here, occ_next
            )
        self.build_s = time.perf_counter() - t0

    @property
    def dim(self) -> int:
        return self.layout.dim

    @property
    def names(self) -> tuple[str, ...]:
        return self.layout.names

    def _replay(self, starts, ends, end_row, cell, action, nxt, collides, occ_here, occ_next) -> None:
        """Walk episodes ``starts..ends`` step by step, all at once, as :class:`MemoryNavEnv` senses them."""
        lay = self.layout
        maps_n = len(lay.channels) + int(lay.visits)
        p = lay.padded_cells
        b = len(starts)
        maps = np.zeros((b, maps_n, p), np.int16)
        maps[:, 0] = lay.sensed_init
        flat = maps.reshape(b, maps_n * p)
        window = lay.stacked_window()
        sensed, visited = 0, 1
        bumped = 2 if lay.channels[-1] == "bumped" else None
        counts = len(lay.channels) if lay.visits else None
        eps = np.arange(b)

        def sense(e, c, occ):
            nbr = lay.neighbor[c]
            maps[e[:, None], sensed, nbr] = np.maximum(maps[e[:, None], sensed, nbr], occ)
            maps[e, visited, lay.pad[c]] = 1
            if counts is not None:
                maps[e, counts, lay.pad[c]] += 1

        def read(e, c):
            win = np.take_along_axis(flat[e], window[c], 1)
            if counts is not None:
                win[:, -1] = np.clip(win[:, -1] - 1, 0, VISITS_CAP)
            return win.astype(np.uint8)

        sense(eps, cell[starts], occ_here[starts])
        lengths = ends - starts + 1
        for k in range(int(lengths.max())):
            e = eps[lengths > k]
            r = starts[e] + k
            self.window[r] = read(e, cell[r])
            if bumped is not None:
                hit = collides[r]
                maps[e[hit], bumped, lay.neighbor[cell[r[hit]], action[r[hit]]]] = 1
            sense(e, nxt[r], occ_next[r])
            last = r == ends[e]
            if last.any():
                self.window[end_row + e[last]] = read(e[last], nxt[r[last]])

    def extend(self, batch: dict[str, np.ndarray], idx: np.ndarray) -> dict[str, np.ndarray]:
        """d3rlpy's minibatch arrays of rows ``idx`` (:meth:`Relabeller.transitions`) with the window appended to
        both observations; a terminal step's next observation stays zero, as d3rlpy's transition picker gives it."""
        idx = np.asarray(idx, np.int64)
        nxt = self.window[self.next_row[idx]].astype(np.float32)
        nxt[batch["terminals"][:, 0] > 0] = 0.0
        return {
            **batch,
            "observations": np.concatenate([batch["observations"], self.window[idx].astype(np.float32)], 1),
            "next_observations": np.concatenate([batch["next_observations"], nxt], 1),
        }

    def arrays(self, a: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The log's arrays (:meth:`LoggedDataset.arrays`) with the window appended to ``obs`` and ``next_obs``."""
        n = len(a["action"])
        return {
            **a,
            "obs": np.concatenate([a["obs"], self.window[:n].astype(np.float32)], 1),
            "next_obs": np.concatenate([a["next_obs"], self.window[self.next_row].astype(np.float32)], 1),
        }


#: The memory windows of the most recently opened logs in this process (the benchmark trains many agents on each),
#: each served only for the transitions and twin it was built from (:mod:`dtradar_rl.offline.log_cache`).
CACHE_SIZE = 2
_CACHE: LogCache[MemorySenses] = LogCache("memory window", CACHE_SIZE)


def senses_content(logged: LoggedDataset, mdp: GridMDP, radius: int, bumps: bool, visits: bool) -> str:
    """What a log's memory windows follow from: its transitions, the twin's moves and the window's layout."""
    return log_content(logged, mdp.next_cell, mdp.collides, f"{mdp.nx}x{mdp.ny} r{radius} b{bumps:d} v{visits:d}")


def memory_senses(logged: LoggedDataset, mdp: GridMDP) -> MemorySenses:
    """The :class:`MemorySenses` of a log with :data:`MEMORY_SETTINGS`, kept for the next runs in this process; a
    kept one of other transitions or another twin under the same folder and version is built again, saying so."""
    s = MEMORY_SETTINGS
    radius, bumps, visits = s["memory_radius"], s["memory_bumps"], s["memory_visits"]
    return _CACHE.get(
        (str(logged.path), logged.name, logged.version),
        senses_content(logged, mdp, radius, bumps, visits),
        lambda: MemorySenses(logged, mdp, radius=radius, bumps=bumps, visits=visits),
        where=f"{logged.name}@{logged.version}",
    )


__all__ = ["MemorySenses", "memory_senses"]
