"""Tabular Q-learning online against the table, readable top to bottom (the tabular counterpart of
:mod:`dtradar_rl.train.dqn`).

    from dtradar_rl.tabular.qlearning import QLearningConfig, learn
    result = learn(QLearningConfig(scene="cubicle"))
    result.policy        # a TablePolicy: the greedy move of every (believed cell, target)

The same environment as the DQN's: :class:`~dtradar_rl.envs.batched.BatchedNavEnv` with ``num_envs`` robots on the
training twin, random connected pairs, the ``geodesic`` reward and the paper's ``total_env_steps`` budget (the
default DQN preset's, :data:`~dtradar_rl.train.config.DEFAULT_PRESET`: 256 robots, 600 K steps on a twin of up to
1 200 free cells), without its obstacle augmentation, measurement noise or memory (a table has no room for them).

The table is ``Q[believed cell, target cell, action]`` (float32, every cell of the grid in both axes, so a
:class:`~dtradar_rl.tabular.table_policy.TablePolicy` reads it with no renumbering); one that would take more than
``max_table_gib``, or (with its greedy moves) more than the memory available (:mod:`dtradar_rl.tabular.memory`), is
refused before anything is allocated (:class:`~dtradar_rl.tabular.table_policy.TooLargeError`). The robot acts
from what it senses: its believed cell is the nearest blueprint fingerprint of
the radio features in its observation and its target the cell of the observation's target ``x, y``
(:class:`~dtradar_rl.tabular.table_policy.Localiser`). The lookup runs on the observation, not on a precomputed map
``true cell -> believed cell``: it is the one :class:`TablePolicy` acts with (so training and evaluation localise the
same way, to the tie), it costs two k-d tree queries per step (well under the env's step on 256 robots) and it still
holds where the features are measured with noise.

One step of the loop, all robots at once:

1. act ε-greedily on ``Q[b, g]`` (ties between equal values broken at random: an untried row is all zeros, and
   ``argmax`` would always try ``X-`` first);
2. step the env, localise the next observation (``b'``; the target does not change within an episode);
3. ``Q[b, g, a] += lr · (r + γ · (1 - terminated) · max Q[b', g] - Q[b, g, a])`` (truncation is not termination: it
   bootstraps through, as the DQN does); robots that share ``(b, g, a)`` in one step update it once.
   **Cells without radio features**: on a free cell that no propagation path reaches (13 of Dallas Q3's 1 950) the
   robot senses nothing, all such cells match the same fingerprint, some other cell's, and their moves would be
   written into that cell's row (on Dallas Q3 a crossing in the middle of the map, whose row then said "collision"
   for moves that are free there: 0.83 against 0.95 greedy success after 60 K steps of Dyna). So a step that begins
   on such a cell is not learned from, and one that ends on one learns, as its next cell, the cell the move led to
   on the training twin's map (from the believed cell; the map the reward already reads). Acting stays as
   :class:`TablePolicy` acts: on such a cell, by the nearest fingerprint;
4. reset the finished robots and localise their new observations.

ε decays linearly from ``eps_start`` to ``eps_end`` over ``eps_decay_fraction`` of the budget, the learning rate
linearly from ``lr`` to ``lr_end``. The defaults were chosen by a small measurement on the cubicle
(``bench/bench_tabular.py --sweep``, docs: Tabular RL).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import write_atomic
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.tabular.memory import check_memory, table_parts
from dtradar_rl.tabular.table_policy import (
    OBS_PRESET,
    Localiser,
    TablePolicy,
    check_table_size,
    greedy_actions,
)
from dtradar_rl.task.config import ConfigError, JobConfig
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.rewards import check_reward
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.twins import load_dataset


# -- settings --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class QLearningConfig(JobConfig):
    """Tabular Q-learning online on the navigation MDP of one twin (module docstring)."""

    revision: str | None = None
    """dataset version tag or hash (default: the newest)"""
    reward: str = "geodesic"
    """reward: paper (exact), scaled, euclidean or geodesic (shaped; see dtradar_rl.task.rewards), as the DQN's"""
    max_steps: int = 0
    """episode step limit (truncation); 0 = 4 * (nx + ny)"""
    num_envs: int = 256
    """robots stepped together in the batched environment (the DQN's default)"""
    total_env_steps: int = 600_000
    """training budget in environment steps (all robots together); the paper's 600K (the default DQN's on a twin of
    up to 1 200 free cells)"""
    gamma: float = 0.5
    """discount factor (the geodesic reward rewards every step along a shortest path, so a short horizon suffices)"""
    lr: float = 1.0
    """learning rate of the table's updates at the start (1 = replace the entry by its target: the moves are
    deterministic on the training twin)"""
    lr_end: float = 1.0
    """learning rate at the end of the budget, reached linearly (negative = constant lr)"""
    eps_start: float = 1.0
    """initial exploration rate"""
    eps_end: float = 0.05
    """final exploration rate"""
    eps_decay_fraction: float = 0.4
    """fraction of the budget over which exploration decays linearly from eps_start to eps_end"""
    max_table_gib: float = 2.0
    """refuse a table (float32 cells x targets x 4) larger than this many GiB, before it is allocated"""
    save: bool = True
    """write config.json, result.json and the greedy table (actions.npy, table.json) to the output directory"""

    #: the learner's name: its output folder and its label in reports
    learner = "qlearning"

    @property
    def dataset_name(self) -> str:
        return f"{self.scene}/{self.variant}" + (f"@{self.revision}" if self.revision else "")

    @property
    def out_dir(self) -> Path:
        return Path(self.out or run_dir(self.scene, self.learner))

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(1, "num_envs", "total_env_steps")
        self.check_at_least(0, "max_steps")
        if not 0 <= self.gamma < 1:
            raise ConfigError(f"--gamma must be in [0, 1), got {self.gamma}", hint="the default is 0.5")
        if not 0 < self.lr <= 1:
            raise ConfigError(f"--lr must be in (0, 1], got {self.lr}", hint="1 replaces an entry by its target")
        if self.lr_end == 0 or self.lr_end > 1:
            raise ConfigError(
                f"--lr-end must be in (0, 1], or negative for a constant --lr, got {self.lr_end}",
                hint="0 would stop learning at the end of the budget",
            )
        self.check_within(0, 1, "eps_start", "eps_end", "eps_decay_fraction")
        if not self.max_table_gib > 0:
            raise ConfigError(f"--max-table-gib must be > 0, got {self.max_table_gib}")

    def validate(self) -> QLearningConfig:
        super().validate()
        check_reward(self.reward)
        return self

    @property
    def max_table_bytes(self) -> int:
        return int(self.max_table_gib * 2**30)


@dataclass
class TabularResult:
    """What :func:`learn` returns: the table, its greedy policy and how the run went."""

    q: torch.Tensor  # float32[cells, cells, 4]
    policy: TablePolicy
    out_dir: Path | None
    env_steps: int
    #: entries of the table updated from real transitions (with hindsight: for every target; planned ones: stats)
    updates: int
    episodes: int
    wall_s: float
    #: success rate, steps and collisions over the last 10 % of training episodes
    final: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)


def epsilon(cfg: QLearningConfig, env_steps: int) -> float:
    """Linear decay from ``eps_start`` to ``eps_end`` over ``eps_decay_fraction`` of the budget."""
    span = cfg.eps_decay_fraction * cfg.total_env_steps
    frac = 1.0 if span <= 0 else min(1.0, env_steps / span)
    return cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)


def learning_rate(cfg: QLearningConfig, env_steps: int) -> float:
    """Linear from ``lr`` to ``lr_end`` over the budget (constant ``lr`` when ``lr_end`` is negative)."""
    if cfg.lr_end < 0:
        return cfg.lr
    return cfg.lr + min(1.0, env_steps / cfg.total_env_steps) * (cfg.lr_end - cfg.lr)


# -- the pieces of a step ------------------------------------------------------------------------------------------
def new_table(cfg: QLearningConfig, cells: int) -> torch.Tensor:
    """``float32[cells, cells, 4]`` zeros, or :class:`TooLargeError` before allocating it."""
    check_table_size(cells, cells, cfg.max_table_bytes, name=f"the Q table of {cfg.dataset_name}")
    return torch.zeros((cells, cells, 4), dtype=torch.float32)


def greedy(values: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """``long[n]``: the best action of each row of ``values [n, 4]``, ties broken uniformly at random."""
    best = values == values.max(1, keepdim=True).values
    score = torch.rand(values.shape, generator=gen).masked_fill_(~best, -1.0)
    return score.argmax(1)


def epsilon_greedy(values: torch.Tensor, eps: float, gen: torch.Generator) -> torch.Tensor:
    explore = torch.rand(values.shape[0], generator=gen) < eps
    return torch.where(explore, torch.randint(4, (values.shape[0],), generator=gen), greedy(values, gen))


def first_of_each(keys: torch.Tensor) -> torch.Tensor:
    """Indices of the first occurrence of every distinct value of ``keys`` (so a shared entry is updated once)."""
    uniq, inverse = torch.unique(keys, return_inverse=True)
    first = torch.full((uniq.numel(),), keys.numel(), dtype=torch.long)
    return first.scatter_reduce_(0, inverse, torch.arange(keys.numel()), "amin")


def td_update(q, b, g, a, reward, b_next, terminal, gamma: float, lr: float) -> int:
    """One Q-learning update of the entries ``(b, g, a)`` (1-D, one per robot; a repeated entry once); returns how
    many entries moved."""
    keep = first_of_each((b * q.shape[1] + g) * 4 + a)
    b, g, a, reward, b_next, terminal = b[keep], g[keep], a[keep], reward[keep], b_next[keep], terminal[keep]
    target = reward + gamma * (~terminal).float() * q[b_next, g].max(1).values
    q[b, g, a] += lr * (target - q[b, g, a])
    return int(keep.numel())


def make_env(cfg: QLearningConfig, ds: Dataset, normalizer: Normalizer) -> BatchedNavEnv:
    """The DQN's environment without augmentation, noise or memory: ``goal`` observations, the config's reward."""
    return BatchedNavEnv.from_dataset(
        ds,
        cfg.num_envs,
        obs=OBS_PRESET,
        normalizer=normalizer,
        reward=cfg.reward,
        max_steps=cfg.max_steps or None,
        seed=cfg.seed,
    )


class QLearner:
    """The table and its update from real transitions (:class:`~dtradar_rl.tabular.dyna.DynaLearner` adds a model
    and planning)."""

    def __init__(self, cfg: QLearningConfig, env: BatchedNavEnv, gen: torch.Generator):
        self.cfg, self.env, self.gen = cfg, env, gen
        self.q = new_table(cfg, env.mdp.num_cells)
        self.updates = 0

    def observe(self, b, g, a, reward, b_next, collided, terminal, env_steps: int) -> None:
        """Learn from one batch of real transitions ``(b, g, a) -> (reward, b_next)``."""
        self.updates += td_update(
            self.q, b, g, a, reward, b_next, terminal, self.cfg.gamma, learning_rate(self.cfg, env_steps)
        )

    def stats(self) -> dict[str, Any]:
        return {"updates": self.updates}


# -- the loop --------------------------------------------------------------------------------------------------------
def run(
    cfg: QLearningConfig,
    make_learner: Callable[[QLearningConfig, BatchedNavEnv, torch.Generator], QLearner],
    dataset: Dataset | None = None,
    *,
    normalizer: Normalizer | None = None,
    callback: Callable[[torch.Tensor, int, float], bool] | None = None,
) -> TabularResult:
    """The online loop of every tabular learner (module docstring). ``callback(q, env_steps, train_s)`` runs after
    every batch of steps with the seconds spent in the loop so far (its own time not counted, nor in ``wall_s``) and
    stops the run by returning True."""
    cfg = cfg.validate()
    t_start = time.perf_counter()
    torch.set_num_threads(cfg.threads or auto_threads())
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    normalizer = normalizer or Normalizer.fit(ds)
    loop = _start(cfg, make_learner, ds, normalizer)
    callback_s = _train(cfg, loop, callback, t_start)
    wall = time.perf_counter() - t_start - callback_s
    return _result(cfg, loop, ds, normalizer, wall)


_MakeLearner = Callable[[QLearningConfig, BatchedNavEnv, torch.Generator], QLearner]
_Callback = Callable[[torch.Tensor, int, float], bool]


@dataclass
class _Loop:
    """What the online loop carries from one batch of steps to the next."""

    env: BatchedNavEnv
    locate: Localiser
    gen: torch.Generator
    learner: QLearner
    next_cell: torch.Tensor  # the training twin's map (cell, action) -> cell, for moves that end without radio
    q: torch.Tensor
    b: torch.Tensor  # believed cell of every robot
    g: torch.Tensor  # target cell of every robot
    heard: torch.Tensor  # whether the robot senses radio features where it stands
    ep_collisions: torch.Tensor
    env_steps: int = 0
    episodes: list[tuple[int, int, int, bool]] = field(default_factory=list)  # (env_step, steps, collisions, success)


def _start(cfg: QLearningConfig, make_learner: _MakeLearner, ds: Dataset, normalizer: Normalizer) -> _Loop:
    """The env, the learner and the robots' first observations (:class:`TooLargeError` first if the table won't fit)."""
    # refused before the env is made: a run that cannot hold its table should not first spend the time to build one
    cells = ds.shape[0] * ds.shape[1]
    check_table_size(cells, cells, cfg.max_table_bytes, f"the Q table of {ds.name}")
    check_memory(
        f"{cfg.learner} on {ds.name}",
        table_parts(cells, cells),
        hint="learn on a twin of coarser cells (a scene built with a larger --cell-m)",
    )
    env = make_env(cfg, ds, normalizer)
    locate = Localiser(ds, normalizer)
    # the learner's generator, seeded apart from the env's (which takes cfg.seed)
    gen = torch.Generator()
    gen.manual_seed(cfg.seed + 1)
    learner = make_learner(cfg, env, gen)
    next_cell = torch.as_tensor(env.mdp.next_cell)
    ep_collisions = torch.zeros(cfg.num_envs, dtype=torch.long)
    env.reset()
    obs = env.observe()
    b, g = (torch.from_numpy(x) for x in locate(obs))
    heard = torch.from_numpy(locate.hears(obs))
    return _Loop(env, locate, gen, learner, next_cell, learner.q, b, g, heard, ep_collisions)


def _train(cfg: QLearningConfig, loop: _Loop, callback: _Callback | None, t_start: float) -> float:
    """Step all robots until the budget is spent or ``callback`` stops the run; returns the seconds spent in the
    callback (not counted as training time)."""
    callback_s = 0.0
    t_loop = time.perf_counter()
    next_log = cfg.total_env_steps // 10
    while loop.env_steps < cfg.total_env_steps:
        eps = epsilon(cfg, loop.env_steps)
        _step(cfg, loop, eps)
        if callback is not None:
            t_cb = time.perf_counter()
            stop = callback(loop.q, loop.env_steps, t_cb - t_loop - callback_s)
            callback_s += time.perf_counter() - t_cb
            if stop:
                break
        if cfg.verbose and loop.env_steps >= next_log:
            s = summary(loop.episodes)
            print(
                f"[{time.perf_counter() - t_start:6.1f}s] {cfg.learner} steps {loop.env_steps:>8d}  episodes "
                f"{len(loop.episodes):>6d}  eps {eps:.3f}  success {s.get('success_rate', 0):.3f}  "
                f"updates {loop.learner.updates}",
                flush=True,
            )
            next_log += cfg.total_env_steps // 10
    return callback_s


def _step(cfg: QLearningConfig, loop: _Loop, eps: float) -> None:
    """One step of all robots (module docstring, steps 1-4)."""
    b, g = loop.b, loop.g
    # 1. act epsilon-greedily on what the robots believe
    a = epsilon_greedy(loop.q[b, g], eps, loop.gen)
    # 2. step, localise where the robots got to
    next_obs, reward, terminated, truncated, info = loop.env.step(a)
    b_next = torch.from_numpy(loop.locate.believed(next_obs))
    heard_next = torch.from_numpy(loop.locate.hears(next_obs))
    loop.env_steps += cfg.num_envs
    # 3. learn from the steps that begin where the robot senses radio features (one that ends where it senses
    # none learns the cell its move led to on the training twin's map)
    ok, c = loop.heard, info["collision"]
    landed = torch.where(heard_next, b_next, loop.next_cell[b, a])
    loop.learner.observe(b[ok], g[ok], a[ok], reward[ok], landed[ok], c[ok], terminated[ok], loop.env_steps)
    # 4. book-keeping, reset the finished robots
    loop.ep_collisions += info["collision"].long()
    loop.b, loop.heard = b_next, heard_next
    done = terminated | truncated
    if bool(done.any()):
        _reset_finished(loop, done, terminated, info)


def _reset_finished(loop: _Loop, done: torch.Tensor, terminated: torch.Tensor, info: dict[str, Any]) -> None:
    """Record the robots' finished episodes, reset them and localise their new observations."""
    idx = torch.nonzero(done, as_tuple=True)[0]
    loop.episodes += [
        (loop.env_steps, int(info["steps"][i]), int(loop.ep_collisions[i]), bool(terminated[i])) for i in idx.tolist()
    ]
    loop.ep_collisions[idx] = 0
    loop.env.reset_where(done)
    fresh = loop.env.observe()[idx]
    b_new, g_new = loop.locate(fresh)
    loop.b[idx], loop.g[idx] = torch.from_numpy(b_new), torch.from_numpy(g_new)
    loop.heard[idx] = torch.from_numpy(loop.locate.hears(fresh))


def _result(cfg: QLearningConfig, loop: _Loop, ds: Dataset, normalizer: Normalizer, wall: float) -> TabularResult:
    """The table's greedy policy and how the run went, written to the output directory when ``cfg.save``."""
    policy = TablePolicy(ds, greedy_actions(loop.q), normalizer, name=cfg.learner)
    n_episodes = len(loop.episodes)
    stats = {"env_steps": loop.env_steps, "episodes": n_episodes, "wall_s": wall, **loop.learner.stats()}
    stats["threads"] = torch.get_num_threads()
    out = cfg.out_dir if cfg.save else None
    final = summary(loop.episodes)
    result = TabularResult(loop.q, policy, out, loop.env_steps, loop.learner.updates, n_episodes, wall, final, stats)
    if cfg.save:
        write_result(cfg, result, ds)
    return result


def learn(
    cfg: QLearningConfig,
    dataset: Dataset | None = None,
    *,
    normalizer: Normalizer | None = None,
    callback: Callable[[torch.Tensor, int, float], bool] | None = None,
) -> TabularResult:
    """Tabular Q-learning on ``dataset`` (default: load ``cfg.dataset_name``); see :func:`run`."""
    return run(cfg, QLearner, dataset, normalizer=normalizer, callback=callback)


def summary(episodes: list[tuple]) -> dict[str, float]:
    """Success rate, steps and collisions over the last 10 % of the training episodes."""
    if not episodes:
        return {}
    tail = np.array([e[1:] for e in episodes[-max(1, len(episodes) // 10) :]], dtype=np.float64)
    return {
        "steps": float(tail[:, 0].mean()),
        "collisions": float(tail[:, 1].mean()),
        "success_rate": float(tail[:, 2].mean()),
    }


def write_result(cfg: QLearningConfig, result: TabularResult, ds: Dataset) -> Path:
    """``config.json`` (the config), ``result.json`` (the twin, how the run went) and the greedy table
    (:meth:`TablePolicy.save`) in the output directory."""
    out = cfg.out_dir
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "config.json", json.dumps({"learner": cfg.learner, **cfg.to_dict()}, indent=2) + "\n")
    record = {
        "learner": cfg.learner,
        "dataset": {"name": ds.name, "version": ds.version},
        "stats": result.stats,
        "final": result.final,
        "torch": torch.__version__,
    }
    write_atomic(out / "result.json", json.dumps(record, indent=2, default=str) + "\n")
    result.policy.save(out)
    return out


__all__ = [
    "QLearner",
    "QLearningConfig",
    "TabularResult",
    "epsilon",
    "epsilon_greedy",
    "greedy",
    "learn",
    "learning_rate",
    "make_env",
    "new_table",
    "run",
    "td_update",
]
