"""Relabelling's engine: a logged dataset replayed towards other goals, rewards and terminals exact.

:class:`Relabeller` opens a log on its twin (checked: every row rebuilt with its logged target equals the stored
row), draws goals as a :class:`~dtradar_rl.offline.relabel.RelabelConfig` says and rebuilds d3rlpy's transition
arrays for them; :func:`relabel` replays every step once, :func:`relabelled_mdp_dataset` as a plain d3rlpy dataset.
What the sources and mixes mean: :mod:`dtradar_rl.offline.relabel`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.offline.formats import as_logged, import_d3rlpy, quiet_d3rlpy
from dtradar_rl.offline.log_cache import LogCache, log_content
from dtradar_rl.offline.log_settings import parent_version
from dtradar_rl.offline.relabel import (
    FALLBACK,
    FUTURE,
    NEXT,
    RANDOM,
    ROW_ACTION,
    ROW_CELL,
    ROW_COLLIDES,
    ROW_LAST,
    ROW_NEXT,
    ROW_NEXT_ACTION,
    ROW_TARGET,
    SOURCES,
    RelabelConfig,
)
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.rewards import potential_kind, reward_fn
from dtradar_rl.task.twins import load_dataset


class Relabeller:
    """A logged dataset and its twin, ready to replay any of its steps towards any goal (module docstring).

    Built once per logged version (:func:`relabeller`): the log's cells, moves and targets, the twin's next cells,
    collisions, components and observation tables, and for the ``geodesic`` reward the breadth-first distances to
    every cell that can be a goal. Checks that every logged row is what the twin gives for its logged target."""

    def __init__(self, logged: LoggedDataset | str, ds: Dataset | None = None):
        t0 = time.perf_counter()
        logged = as_logged(logged)
        meta = logged.meta
        ds = ds if ds is not None else load_dataset(meta["parent"])
        self.name = f"{logged.name}@{logged.version}"
        #: the sha256 of the transitions it was built from (a sampler checks its parts are of one log)
        self.log = log_content(logged)
        if ds.name != meta.get("parent") or parent_version(ds) != meta.get("parent_version"):
            raise SchemaMismatchError(
                f"{self.name} was logged on {meta.get('parent')} version {meta.get('parent_version')}, not on "
                f"{ds.name} version {parent_version(ds)}",
                hint=f"relabel it with its own twin (python -m dtradar_data pull {meta.get('parent')}@<version>)",
            )
        mdp = GridMDP.from_dataset(ds)
        if isinstance(mdp, MovingGridMDP):
            raise SchemaMismatchError(
                f"{self.name} was logged on the moving twin {ds.name}: its observations depend on the snapshot, which "
                "the logged table does not keep, so they cannot be rebuilt for another goal",
                hint="relabel a log of a static twin (blueprint, dynamic)",
            )
        settings = meta.get("settings") or {}
        preset = (meta.get("observations") or {}).get("preset")
        self.reward_name = settings.get("reward")
        table = build_observations(ds, preset, Normalizer.from_dict(meta["normalizer"]))
        if table.target_part.shape[1] == 0:
            raise SchemaMismatchError(
                f"{self.name} is observed with the {preset!r} preset, which has no target: a relabelled goal would be "
                "invisible to the policy",
                hint="relabel a log observed with the goal or neighbors preset",
            )
        a = logged.arrays()
        n = len(a["action"])
        self.mdp, self.cell_part, self.target_part = mdp, table.cell_part, table.target_part
        self.cell = a["cell"].astype(np.int64)
        self.action = a["action"].astype(np.int64)
        self.target = a["target"].astype(np.int64)
        self.next = mdp.next_cell[self.cell, self.action]
        self.collides = mdp.collides[self.cell, self.action]
        ends = np.flatnonzero(a["terminated"] | a["truncated"])
        rows = np.arange(n)
        #: the index of the last row of each row's episode
        self.last = ends[np.searchsorted(ends, rows)]
        inside = rows < self.last
        #: d3rlpy's next action: the logged one inside an episode, 0 after an episode's last step
        self.next_action = np.where(inside, self.action[np.minimum(rows + 1, n - 1)], 0)
        if (self.next[inside] != self.cell[rows[inside] + 1]).any():
            i = int(np.flatnonzero(self.next[inside] != self.cell[rows[inside] + 1])[0])
            raise SchemaMismatchError(
                f"{self.name}: row {rows[inside][i]}'s move leads to another cell than the next row's on {ds.name}",
                hint="the log was not made on this twin; relabel it with its own twin",
            )
        # random goals: members[first[c] + j + (j >= rank[cell])] of the cell's component c, j < size - 1
        cells = mdp.pair_cells()
        order = np.argsort(mdp.component[cells], kind="stable")
        self.members = cells[order]
        comp = mdp.component[self.members]
        self.comp_size = np.bincount(comp, minlength=int(mdp.component.max()) + 1)
        self.comp_first = np.r_[0, np.cumsum(self.comp_size)[:-1]]
        self.rank = np.zeros(mdp.num_cells, np.int64)
        self.rank[self.members] = np.arange(self.members.size) - self.comp_first[comp]
        iy, ix = np.divmod(np.arange(mdp.num_cells), mdp.nx)
        #: ``float32[cells, 2]``: each cell's ``(ix, iy)``, as the batched env holds them
        self.xy = np.stack([ix, iy], 1).astype(np.float32)
        #: ``int64[cells, 3]``: a cell's component's first member, the component's size - 1, the cell's rank in it
        self._cell_comp = np.zeros((mdp.num_cells, 3), np.int64)
        free = mdp.component >= 0
        c = mdp.component[free]
        self._cell_comp[free] = np.stack([self.comp_first[c], self.comp_size[c] - 1, self.rank[free]], 1)
        #: ``int64[steps, 7]``: each logged row's columns (:data:`ROW_CELL` ...), one cache line per row
        self._rows = np.stack(
            [self.cell, self.action, self.target, self.next, self.last, self.next_action, self.collides], 1
        ).astype(np.int64)
        self.potential = potential_kind(self.reward_name)
        if self.potential == "geodesic":  # one row per cell that can be a goal (every pair cell), flattened
            self.goal_row = np.full(mdp.num_cells, -1, np.int64)
            self.goal_row[cells] = np.arange(cells.size)
            self.dist = mdp.bfs_distances_many(cells).astype(np.int32).ravel()
        self._check(a)
        self.build_s = time.perf_counter() - t0

    def __len__(self) -> int:
        return len(self.action)

    def _check(self, a: dict[str, np.ndarray]) -> None:
        """Every logged row equals the row rebuilt for its logged target, else :class:`SchemaMismatchError`."""
        mine = self.transitions(np.arange(len(self)), self.target, zero_terminal=False)
        logged = {
            "observations": a["obs"],
            "next_observations": a["next_obs"],
            "rewards": a["reward"].astype(np.float32),
            "terminals": a["terminated"],
        }
        for key, theirs in logged.items():
            ours = mine[key].reshape(theirs.shape).astype(theirs.dtype)
            same = (ours == theirs).reshape(len(ours), -1).all(1)
            if not same.all():
                i = int(np.flatnonzero(~same)[0])
                raise SchemaMismatchError(
                    f"{self.name}: row {i}'s {key} differs from what its twin gives for the logged cell, move and "
                    "target: the log does not replay on this twin",
                    hint="relabel a log with the twin (and version) it was logged on",
                )

    # -- goals -------------------------------------------------------------------------------------------------
    def goals(self, idx: np.ndarray, cfg: RelabelConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``(goal cells, sources)`` for logged rows ``idx`` by ``cfg``'s mix; a source is an index of
        :data:`SOURCES`, or :data:`FALLBACK` where the drawn goal was the current cell and became the logged target."""
        goal, source, _ = self._goals(np.asarray(idx, np.int64), cfg, rng)
        return goal, source

    def _goals(self, idx: np.ndarray, cfg: RelabelConfig, rng: np.random.Generator):
        rows = self._rows[idx]  # one gather of everything a row needs (random gathers cost cache misses)
        cell, target = rows[:, ROW_CELL], rows[:, ROW_TARGET]
        goal = target.copy()
        m = idx.size
        if cfg.is_identity:
            return goal, np.zeros(m, np.int64), rows
        cum = np.cumsum(cfg.probabilities)
        cum /= cum[-1]
        source = np.minimum(np.searchsorted(cum, rng.random(m), side="right"), len(SOURCES) - 1)
        f = np.flatnonzero(source == FUTURE)
        if f.size:
            k = rng.geometric(1.0 - cfg.discount, f.size)
            goal[f] = self.next[np.minimum(idx[f] + (k - 1), rows[f, ROW_LAST])]
        r = np.flatnonzero(source == RANDOM)
        if r.size:
            first, span, rank = self._cell_comp[cell[r]].T
            j = np.floor(rng.random(r.size) * span).astype(np.int64)
            goal[r] = self.members[first + j + (j >= rank)]
        nx_ = np.flatnonzero(source == NEXT)
        goal[nx_] = rows[nx_, ROW_NEXT]
        same = goal == cell
        goal[same] = target[same]
        source[same] = FALLBACK
        return goal, source, rows

    # -- transitions -------------------------------------------------------------------------------------------
    def rewards(self, idx: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """``float32``: the logged reward function of rows ``idx``' moves towards ``goal``, computed like the batched
        env that logs (:meth:`dtradar_rl.envs.batched.BatchedNavEnv._reward`)."""
        return self._rewards(self._rows[np.asarray(idx, np.int64)], np.asarray(goal, np.int64))

    def _rewards(self, rows: np.ndarray, goal: np.ndarray) -> np.ndarray:
        # The batched env's float32 operations in its order. numpy's float32 +, -, *, / round like torch's; the square
        # root does not (torch's is not correctly rounded), so the euclidean potential takes torch's.
        cell, nxt = rows[:, ROW_CELL], rows[:, ROW_NEXT]
        g, n = self.xy[goal], self.xy[nxt]
        dx, dy = g[:, 0] - n[:, 0], g[:, 1] - n[:, 1]
        if self.potential == "geodesic":
            at = self.goal_row[goal] * self.mdp.num_cells
            pb, pa = self.dist[at + cell].astype(np.float32), self.dist[at + nxt].astype(np.float32)
        elif self.potential == "euclidean":
            c = self.xy[cell]
            bx, by = g[:, 0] - c[:, 0], g[:, 1] - c[:, 1]
            pb = torch.sqrt(torch.from_numpy(bx * bx + by * by)).numpy()
            pa = torch.sqrt(torch.from_numpy(dx * dx + dy * dy)).numpy()
        else:
            pb = pa = np.zeros((), np.float32)
        out = reward_fn(
            self.reward_name,
            d2_after=dx * dx + dy * dy,
            pot_before=pb,
            pot_after=pa,
            collision=rows[:, ROW_COLLIDES].astype(np.float32),
            reached=(nxt == goal).astype(np.float32),
            diag2=self.mdp.diag2,
        )
        return np.asarray(out, np.float32)

    def transitions(self, idx: np.ndarray, goal: np.ndarray, *, zero_terminal: bool = True) -> dict[str, np.ndarray]:
        """Rows ``idx`` replayed towards ``goal``: d3rlpy's minibatch arrays (``observations``, ``actions``,
        ``rewards``, ``next_observations``, ``next_actions``, ``terminals``; float32, the scalars as ``[m, 1]``).
        ``zero_terminal``: a terminal step's next observation and action are zero (d3rlpy's transition picker)."""
        return self._transitions(self._rows[np.asarray(idx, np.int64)], np.asarray(goal, np.int64), zero_terminal)

    def _transitions(self, rows: np.ndarray, goal: np.ndarray, zero_terminal: bool = True) -> dict[str, np.ndarray]:
        nxt = rows[:, ROW_NEXT]
        tp = self.target_part[goal]
        obs = np.concatenate([self.cell_part[rows[:, ROW_CELL]], tp], 1)
        next_obs = np.concatenate([self.cell_part[nxt], tp], 1)
        term = nxt == goal
        next_action = rows[:, ROW_NEXT_ACTION].astype(np.float32)
        if zero_terminal:
            next_obs[term] = 0.0
            next_action[term] = 0.0
        col = lambda v: np.asarray(v, np.float32).reshape(-1, 1)  # noqa: E731
        return {
            "observations": obs,
            "actions": col(rows[:, ROW_ACTION]),
            "rewards": col(self._rewards(rows, goal)),
            "next_observations": next_obs,
            "next_actions": col(next_action),
            "terminals": col(term),
        }

    def batch(self, idx: np.ndarray, cfg: RelabelConfig, rng: np.random.Generator):
        """``(d3rlpy's minibatch arrays, sources)`` of rows ``idx`` towards goals drawn by ``cfg``."""
        goal, source, rows = self._goals(np.asarray(idx, np.int64), cfg, rng)
        return self._transitions(rows, goal), source


CACHE_SIZE = 2
#: The relabellers of the most recently opened logged versions in this process (see :func:`relabeller`), each served
#: only for the transitions it was built from (:mod:`dtradar_rl.offline.log_cache`).
_CACHE: LogCache[Relabeller] = LogCache("relabeller", CACHE_SIZE)


def relabeller(logged: LoggedDataset | str, ds: Dataset | None = None) -> Relabeller:
    """The :class:`Relabeller` of a logged version on its twin, kept for the next runs in this process (the
    :data:`CACHE_SIZE` most recent): the benchmark trains many agents on each log. Relabelling never writes to it.
    A kept one built from other transitions under the same folder and version is built again, saying so."""
    logged = as_logged(logged)
    key = (str(logged.path), logged.name, logged.version, parent_version(ds) if ds is not None else "")
    where = f"{logged.name}@{logged.version}"
    return _CACHE.get(key, log_content(logged), lambda: Relabeller(logged, ds), where=where)


@dataclass
class Relabelled:
    """Every logged step replayed towards one drawn goal (:func:`relabel`): the logged table's columns for the goal
    (``obs``, ``action``, ``reward``, ``next_obs``, ``terminated``, ``cell``, ``goal``; ``next_obs`` is the real one
    even on a terminal step) and where each goal came from (``source``: an index of :data:`SOURCES`, or
    :data:`FALLBACK`)."""

    columns: dict[str, np.ndarray]
    config: RelabelConfig

    def __len__(self) -> int:
        return len(self.columns["action"])

    def shares(self) -> dict[str, float]:
        return source_shares(np.bincount(self.columns["source"], minlength=FALLBACK + 1))


def source_shares(counts: np.ndarray) -> dict[str, float]:
    """The share of each source (and of fallbacks) in ``counts`` (``int[5]``)."""
    total = max(1, int(counts.sum()))
    return {name: int(c) / total for name, c in zip((*SOURCES, "fallback"), counts)}


def relabel(logged: LoggedDataset | str, cfg: RelabelConfig, ds: Dataset | None = None) -> Relabelled:
    """Every step of ``logged`` replayed towards a goal drawn by ``cfg`` (one draw per step, from ``cfg.seed``)."""
    rl = relabeller(logged, ds)
    idx = np.arange(len(rl))
    goal, source = rl.goals(idx, cfg, np.random.default_rng(cfg.seed))
    t = rl.transitions(idx, goal, zero_terminal=False)
    columns = {
        "obs": t["observations"],
        "action": rl.action.copy(),
        "reward": t["rewards"][:, 0],
        "next_obs": t["next_observations"],
        "terminated": t["terminals"][:, 0] > 0,
        "cell": rl.cell.copy(),
        "goal": goal,
        "source": source,
    }
    return Relabelled(columns, cfg)


def relabelled_mdp_dataset(logged: LoggedDataset | str, cfg: RelabelConfig, ds: Dataset | None = None):
    """:func:`relabel`'s steps as a d3rlpy ``MDPDataset``: one episode per step (module docstring), so d3rlpy's
    ``transition_count`` is the number of logged steps and each step bootstraps only within itself."""
    d3rlpy = import_d3rlpy()
    c = relabel(logged, cfg, ds).columns
    term = c["terminated"]
    at = np.flatnonzero(~term) + 1  # after each non-terminal step: its next observation, ending in a timeout
    with quiet_d3rlpy():
        return d3rlpy.dataset.MDPDataset(
            observations=np.insert(c["obs"], at, c["next_obs"][~term], axis=0),
            actions=np.insert(c["action"].astype(np.int64), at, 0),
            rewards=np.insert(c["reward"], at, 0.0),
            terminals=np.insert(term.astype(np.float32), at, 0.0),
            timeouts=np.insert(np.zeros(len(term), np.float32), at, 1.0),
            action_space=d3rlpy.constants.ActionSpace.DISCRETE,
            action_size=4,
        )


__all__ = ["CACHE_SIZE", "Relabelled", "Relabeller", "relabel", "relabelled_mdp_dataset", "relabeller", "source_shares"]
