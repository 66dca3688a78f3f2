"""Goal relabelling: any logged dataset seen as goal-conditioned data, with goals drawn from its own trajectories.

A logged step holds the robot's cell, its move and the target it was walking to. The observation is
``[cell_part[cell], target_part[target]]`` (:mod:`dtradar_rl.task.observations`) and the twin's table gives the rest
exactly (the next cell is ``next_cell[cell, action]``, the reward a function of the cells and the target), so the same
step can be replayed towards *another* goal: the target part of ``obs`` and ``next_obs`` is swapped for the goal's, the
reward and the terminal are recomputed for that goal. This is hindsight relabelling (Andrychowicz et al. 2017), the
field's answer for goal-conditioned offline data; OGBench (Park et al. 2024, arXiv 2410.20092) draws *actor* goals
from the future of the same trajectory (geometric) and *value* goals from a mix of the current, future and random
states.

Where a goal comes from (:class:`RelabelConfig`, probabilities summing to 1)
------------------------------------------------------------------------------
``own``     the logged target (no relabelling).
``future``  the cell the same episode reaches ``k`` steps later, ``k >= 1`` geometric with parameter
            ``1 - discount`` (mean ``1 / (1 - discount)`` steps), cut at the episode's last step (whose next cell is
            the target when the episode terminated). ``k = 1`` is this step's own next cell.
``random``  a cell drawn uniformly from the robot's connected component, the robot's own cell excepted.
``next``    this step's own next cell: a one-step success (OGBench's "current state" goal, shifted by one step to
            this MDP's convention that an episode ends on *arriving* at the target).

A drawn goal that is the robot's current cell (``next`` or ``future`` after a bump, a walk that came back) is **not
drawn**: it is replaced by the logged target. The MDP never decides on its own target (an episode ends on arriving,
and a reset never starts on the target), so such a step would be an absorbing state no evaluation visits. How often
it happens is counted (``fallback`` in :attr:`RelabelledSampler.counts` and in a run's ``config.json``).

Rewards and terminals are exact: the terminal is ``next cell == goal``; the reward is the logged reward function
(``paper``, ``scaled``, ``euclidean`` or ``geodesic``, with the breadth-first distances of the twin for ``geodesic``)
computed with the float32 operations of the batched env that logged the data, so a relabelled step equals the step
the env gives from that cell with that action and that target, bit for bit, and ``own`` probability 1 reproduces the
logged table exactly. :class:`Relabeller` checks this on every log it opens (every row rebuilt with its logged target
must equal the stored row), so a log that does not replay on its twin is refused, not relabelled wrongly.

Relabelled steps have no episodes any more. d3rlpy sees them in one of two ways:

- training (:func:`dtradar_rl.offline.trainer.train_offline` with ``--relabel``): :class:`RelabelledSampler`, a
  d3rlpy ``ReplayBuffer`` over the logged episodes (its dataset info, observation shape and transition count are the
  log's) whose minibatches are relabelled transitions, built like the trainer's flat sampler
  (:func:`~dtradar_rl.offline.trainer.fast_sampling`: the same indices from numpy's global generator, the same
  arrays, terminal next observations zero), so every algorithm of :data:`~dtradar_rl.offline.config.ALGORITHMS`
  trains on it unchanged. ``resample="batch"`` draws fresh goals for every minibatch (OGBench's way; a few tens of
  microseconds per batch of 256), ``"run"`` one goal per logged step, fixed for the run.
- a plain d3rlpy dataset (:func:`relabelled_mdp_dataset`): one episode per relabelled step, a terminal step as a
  terminated one-row episode, any other as a two-row episode ending in a timeout (``obs``, then ``next_obs``), so
  ``transition_count`` equals the logged steps and no step bootstraps into another's goal.

Measured (``bench/bench_relabel.py``; expert, medium and mixed logs of the cubicle and Dallas Q3, seed 0, 4 000
updates): the imitation learners (bc, cql) train best on ``own-next`` (half the logged targets, half the next cell),
the Q-learners (bcq, dqn, ddqn, nfq) on ``ogbench``; ``--relabel auto`` picks that mix by algorithm
(:data:`AUTO_MIXES`). Goals from ``random`` alone, or future goals for the Q-learners without random ones, help little.

``--algorithm bc --relabel future`` is **GCBC** (goal-conditioned behaviour cloning, Ghosh et al. 2019; OGBench's
GCBC): DiscreteBC on the logged moves with goals from the future of the same trajectory.

Only static twins: a moving twin's observation depends on the snapshot, which the logged table does not keep.
"""

from __future__ import annotations

import functools
import math
import numbers
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError, unknown_name
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.offline.formats import as_logged, import_d3rlpy, quiet_d3rlpy
from dtradar_rl.offline.logged import parent_version
from dtradar_rl.task.config import Config, ConfigError
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.rewards import potential_kind, reward_fn
from dtradar_rl.task.twins import load_dataset

#: Where a goal can come from (the module docstring), in the order of :class:`RelabelConfig`'s probabilities.
SOURCES: tuple[str, ...] = ("own", "future", "random", "next")
OWN, FUTURE, RANDOM, NEXT = range(4)
#: The count of drawn goals that were the robot's current cell and became the logged target.
FALLBACK = 4
#: The columns of :attr:`Relabeller._rows`.
ROW_CELL, ROW_ACTION, ROW_TARGET, ROW_NEXT, ROW_LAST, ROW_NEXT_ACTION, ROW_COLLIDES = range(7)
#: How often goals are drawn (:attr:`RelabelConfig.resample`).
RESAMPLE: tuple[str, ...] = ("batch", "run")

#: Named mixes (``--relabel <name>``); any other mix is written ``own=0.5,future=0.5``.
MIXES: dict[str, dict[str, float]] = {
    "none": {"own": 1.0},
    # GCBC's goals, OGBench's actor goals: the future of the same trajectory
    "future": {"future": 1.0},
    # half the logged targets, half the future of the trajectory
    "own-future": {"own": 0.5, "future": 0.5},
    # OGBench's value goals (p_curgoal 0.2, p_trajgoal 0.5, p_randomgoal 0.3)
    "ogbench": {"next": 0.2, "future": 0.5, "random": 0.3},
    # every goal the twin allows, drawn uniformly from the robot's component
    "random": {"random": 1.0},
    # half the logged targets, half the step's own next cell: the best measured for the imitation learners
    "own-next": {"own": 0.5, "next": 0.5},
}
#: ``--relabel auto``: the mix each algorithm trained best with on the expert and medium logs of the cubicle and Dallas
#: Q3 (seed 0, 4 000 updates, ``bench/bench_relabel.py``): the imitation learners (bc, and cql, whose conservative term
#: pulls towards the logged moves) on their targets and the next cell, the Q-learners on OGBench's value goals.
AUTO_MIXES: dict[str, str] = {
    "bc": "own-next",
    "cql": "own-next",
    "bcq": "ogbench",
    "dqn": "ogbench",
    "ddqn": "ogbench",
    "nfq": "ogbench",
}
AUTO = "auto"
MIX_FORM = (
    "a named mix ("
    + ", ".join(MIXES)
    + "), auto (the algorithm's best: "
    + ", ".join(f"{a} {m}" for a, m in AUTO_MIXES.items())
    + ") or probabilities like future=0.5,random=0.3,next=0.2"
)
#: Tolerance of "the probabilities sum to 1".
SUM_TOLERANCE = 1e-6
#: The default geometric parameter of ``future`` goals: mean offset 1 / (1 - 0.9) = 10 steps.
DEFAULT_DISCOUNT = 0.9


@dataclass(frozen=True)
class RelabelConfig(Config):
    """Where relabelled goals come from: four probabilities summing to 1, the future goals' discount, a seed."""

    own: float = 1.0
    """probability of the logged target (no relabelling)"""
    future: float = 0.0
    """probability of a cell the same episode reaches later: k >= 1 steps ahead, geometric with parameter
    1 - discount, cut at the episode's last step"""
    random: float = 0.0
    """probability of a cell drawn uniformly from the robot's connected component (its own cell excepted)"""
    next: float = 0.0
    """probability of this step's own next cell (a one-step success)"""
    discount: float = DEFAULT_DISCOUNT
    """future goals: the geometric offset's discount (mean offset 1 / (1 - discount) steps; 0 = the next cell)"""
    seed: int = 0
    """seed of the goal draws (a generator of its own: the minibatch indices stay d3rlpy's)"""
    resample: str = "batch"
    """batch: fresh goals for every minibatch; run: one goal per logged step, drawn once"""

    @property
    def probabilities(self) -> np.ndarray:
        return np.array([getattr(self, s) for s in SOURCES], np.float64)

    @property
    def is_identity(self) -> bool:
        """Every goal is the logged target: the logged transitions as they are."""
        return self.own == 1.0

    def check_ranges(self) -> None:
        for s in SOURCES:
            v = getattr(self, s)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v < 0:
                raise ConfigError(
                    f"relabel probability {s!r} must be a finite number >= 0, got {v!r}",
                    hint=f"give each of {', '.join(SOURCES)} a probability in [0, 1], e.g. --relabel "
                    "future=0.5,random=0.3,next=0.2",
                )
        total = float(self.probabilities.sum())
        if abs(total - 1.0) > SUM_TOLERANCE:
            given = ", ".join(f"{s}={getattr(self, s):g}" for s in SOURCES if getattr(self, s))
            default_own = " (own is 1 unless given: set it to what the others leave)" if self.own == 1.0 else ""
            raise ConfigError(
                f"relabel probabilities must sum to 1, got {total:g} ({given or 'all 0'}){default_own}",
                hint="scale them to sum to 1 (a source not named is 0), e.g. --relabel future=0.5,random=0.3,next=0.2",
            )
        d = self.discount
        if isinstance(d, bool) or not isinstance(d, numbers.Real) or not (math.isfinite(d) and 0 <= d < 1):
            raise ConfigError(
                f"--relabel-discount must be in [0, 1), got {d!r}",
                hint="the future goals' offset is geometric with parameter 1 - discount; e.g. 0.9 (10 steps ahead "
                "on average)",
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise ConfigError(f"relabel seed must be an integer >= 0, got {self.seed!r}")
        if self.resample not in RESAMPLE:
            raise unknown_name("relabel resampling", self.resample, RESAMPLE)

    @classmethod
    def parse(cls, mix: str, algorithm: str | None = None, **kw: Any) -> RelabelConfig:
        """The config of ``mix``: a name of :data:`MIXES`, ``auto`` (:data:`AUTO_MIXES` of ``algorithm``) or
        ``source=p,...`` (sources not named are 0); ``kw`` sets ``discount``, ``seed`` and ``resample``."""
        text = str(mix).strip()
        if text == AUTO:
            if algorithm not in AUTO_MIXES:
                raise ConfigError(
                    f"--relabel auto picks the mix of the algorithm, got algorithm {algorithm!r}",
                    hint="one of " + ", ".join(AUTO_MIXES) + " (or name the mix)",
                )
            text = AUTO_MIXES[algorithm]
        if text in MIXES:
            probs = MIXES[text]
        elif "=" in text:
            probs = {}
            for part in text.split(","):
                name, sep, value = part.partition("=")
                name = name.strip()
                if not sep or not name:
                    raise ConfigError(f"--relabel {text!r}: {part!r} is not source=probability", hint=MIX_FORM)
                if name not in SOURCES:
                    raise unknown_name("relabel goal source", name, SOURCES)
                if name in probs:
                    raise ConfigError(f"--relabel {text!r} names {name!r} twice", hint=MIX_FORM)
                try:
                    probs[name] = float(value)
                except ValueError:
                    raise ConfigError(
                        f"--relabel {text!r}: the probability of {name!r} is {value.strip()!r}, not a number",
                        hint=MIX_FORM,
                    ) from None
        else:
            raise unknown_name("relabel mix", text, MIXES)
        return cls(**{s: float(probs.get(s, 0.0)) for s in SOURCES}, **kw)

    def describe(self) -> str:
        return ",".join(f"{s}={getattr(self, s):g}" for s in SOURCES if getattr(self, s))


#: The observation presets with a target part (the others cannot show a relabelled goal to the policy).
TARGET_PRESETS: tuple[str, ...] = ("goal", "neighbors")


def not_relabellable(ds: Dataset, preset: str) -> str | None:
    """Why a log of twin ``ds`` observed with ``preset`` cannot be relabelled (None when it can): a moving twin (its
    observations depend on the snapshot) or a preset without a target. ``--relabel auto`` then trains on the logged
    targets; a mix named explicitly is refused by :class:`Relabeller` instead."""
    if ds.is_moving:
        return f"{ds.name} is a moving twin"
    if preset not in TARGET_PRESETS:
        return f"the {preset!r} observation has no target"
    return None


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


#: The relabellers of the most recently opened logged versions in this process (see :func:`relabeller`).
_CACHE: OrderedDict[tuple[str, str, str, str], Relabeller] = OrderedDict()
CACHE_SIZE = 2


def relabeller(logged: LoggedDataset | str, ds: Dataset | None = None) -> Relabeller:
    """The :class:`Relabeller` of a logged version on its twin, kept for the next runs in this process (the
    :data:`CACHE_SIZE` most recent): the benchmark trains many agents on each log. Relabelling never writes to it."""
    logged = as_logged(logged)
    key = (str(logged.path), logged.name, logged.version, parent_version(ds) if ds is not None else "")
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    out = Relabeller(logged, ds)
    _CACHE[key] = out
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return out


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


@functools.cache
def _sampler_class():
    D = import_d3rlpy().dataset

    class RelabelledSampler(D.ReplayBuffer):
        """A d3rlpy ``ReplayBuffer`` over a log's episodes whose minibatches are relabelled steps (module
        docstring): indices from numpy's global generator like d3rlpy's (and the trainer's flat sampler), goals from a
        generator of the config's seed."""

        def __init__(self, source, relabeller: Relabeller, cfg: RelabelConfig):
            self.__dict__.update(source.__dict__)  # shared, not rebuilt: see the trainer's FlatTransitionSampler
            if self.transition_count != len(relabeller):
                raise SchemaMismatchError(
                    f"the d3rlpy dataset holds {self.transition_count} transitions, the log {len(relabeller)}",
                    hint="relabel the log the d3rlpy dataset was built from",
                )
            self.relabeller, self.config = relabeller, cfg
            self.rng = np.random.default_rng(cfg.seed)
            #: how many drawn goals came from each source (and how many fell back), over every minibatch
            self.counts = np.zeros(FALLBACK + 1, np.int64)
            self.draw_s = 0.0
            self._fixed = None
            if cfg.resample == "run":
                t0 = time.perf_counter()
                idx = np.arange(len(relabeller))
                goal, src = relabeller.goals(idx, cfg, self.rng)
                self._fixed = relabeller.transitions(idx, goal)
                self._fixed_source = src
                self.draw_s = time.perf_counter() - t0

        def sample_transition_batch(self, batch_size: int):
            i = np.random.randint(self.transition_count, size=batch_size)
            if self._fixed is not None:
                batch = {k: v[i] for k, v in self._fixed.items()}
                src = self._fixed_source[i]
            else:
                t0 = time.perf_counter()
                batch, src = self.relabeller.batch(i, self.config, self.rng)
                self.draw_s += time.perf_counter() - t0
            self.counts += np.bincount(src, minlength=FALLBACK + 1)
            return D.TransitionMiniBatch(**batch, intervals=np.ones((batch_size, 1), np.float32), transitions=[])

        def summary(self) -> dict[str, Any]:
            return {
                **self.config.to_dict(),
                "mix": self.config.describe(),
                "drawn": int(self.counts.sum()),
                "shares": source_shares(self.counts),
                "draw_s": self.draw_s,
                "relabeller_build_s": self.relabeller.build_s,
            }

    return RelabelledSampler


def relabelled_sampler(source, relabeller: Relabeller, cfg: RelabelConfig):
    """The d3rlpy dataset a trainer fits on: ``source`` (the log's d3rlpy dataset,
    :func:`~dtradar_rl.offline.formats.to_mdp_dataset`) with relabelled minibatches (:class:`RelabelledSampler`)."""
    return _sampler_class()(source, relabeller, cfg)


def __getattr__(name: str):
    if name == "RelabelledSampler":
        return _sampler_class()
    raise AttributeError(name)


__all__ = [
    "FALLBACK",
    "AUTO_MIXES",
    "MIXES",
    "SOURCES",
    "TARGET_PRESETS",
    "RelabelConfig",
    "Relabelled",
    "Relabeller",
    "not_relabellable",
    "relabel",
    "relabelled_mdp_dataset",
    "relabelled_sampler",
    "relabeller",
]
