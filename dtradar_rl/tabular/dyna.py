"""Dyna-Q online against the table: tabular Q-learning (:mod:`dtradar_rl.tabular.qlearning`) plus a learned model of
the moves and planning updates from it, with hindsight over targets.

    from dtradar_rl.tabular.dyna import DynaConfig, learn
    result = learn(DynaConfig(scene="cubicle"))

The environment, the table ``Q[believed cell, target cell, action]``, the localisation, exploration and the loop are
Q-learning's (:func:`dtradar_rl.tabular.qlearning.run`). What Dyna adds (Sutton 1990, Sutton and Barto ch. 8.2):

* **a model** of the moves, learned from the real transitions: ``model[b, a] = (b', collided)``, the last next
  believed cell and collision seen after action ``a`` from believed cell ``b`` (deterministic: on a static twin a
  move from a cell always ends in the same cell, and localisation maps it to the same belief; ``-1`` until tried);
* **hindsight over targets** (``hindsight``, on by default): the moves do not depend on the target, only the reward
  does, and the reward is a known function of ``(cell, next cell, collided, target)`` (:func:`rewards_for`, the
  env's own reward with the training twin's distance tables, the signal the DQN is trained on too). So one real
  transition ``(b, a) -> (b', collided)`` updates the entry ``Q[b, g, a]`` of *every* training target ``g`` (the
  env's target pool), not only the robot's own target: Kaelbling's "all goals" updating (1993), the tabular form of
  hindsight relabelling (Andrychowicz et al. 2017). With ``hindsight`` off a real transition updates its own
  target's entry, with the env's reward, as in Q-learning;
* **planning**: after every real batch of steps, ``planning_steps`` updates, each of ``planning_batch`` entries
  ``(b, a)`` drawn uniformly from those the model knows, for every training target (``planning_targets`` = 0) or for
  that many targets drawn at random (one draw per planning update), with the model's ``(b', collided)`` and the reward
  function.

A planned or hindsight update is Q-learning's: ``Q[b, g, a] += lr · (r(b, b', collided, g) + γ · [b' != g] ·
max Q[b', g] - Q[b, g, a])``; an entry whose target is its own cell (a robot never acts there: the episode is over)
is left alone. Env steps are the budget, as for every learner; the planning is compute, not experience, and its
cost is in the result's wall time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.tabular.qlearning import (
    QLearner,
    QLearningConfig,
    TabularResult,
    first_of_each,
    learning_rate,
    run,
    td_update,
)
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.rewards import reward_fn


@dataclass(frozen=True)
class DynaConfig(QLearningConfig):
    """Dyna-Q online on the navigation MDP of one twin: Q-learning + a learned model, planning and hindsight over
    targets (module docstring)."""

    hindsight: bool = True
    """a real transition updates the entry of every training target (the moves do not depend on the target; the
    reward is a known function of it), not only its robot's own"""
    planning_steps: int = 1
    """planning updates from the learned model after every batch of real steps (0 = none)"""
    planning_batch: int = 256
    """model entries (believed cell, action) drawn for one planning update"""
    planning_targets: int = 0
    """targets each drawn entry is updated for (0 = every training target; else that many drawn at random)"""

    learner = "dyna"

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(0, "planning_steps", "planning_targets")
        self.check_at_least(1, "planning_batch")


def rewards_for(env: BatchedNavEnv, cell: torch.Tensor, nxt: torch.Tensor, collided: torch.Tensor, rows: torch.Tensor):
    """``float32[m, k]``: the env's reward of the moves ``cell -> nxt`` (``m``, with ``collided``) towards each target
    of its pool rows ``rows`` (``k``): :func:`~dtradar_rl.task.rewards.reward_fn` with the env's own distance tables."""
    target = env.pool[rows][None, :]  # [1, k]
    cell, nxt, collided = cell[:, None], nxt[:, None], collided[:, None]
    dx, dy = env.ix[target] - env.ix[nxt], env.iy[target] - env.iy[nxt]
    if env.potential == "geodesic":
        dist = env.dist[rows]  # [k, cells]
        before, after = dist[:, cell[:, 0]].T.float(), dist[:, nxt[:, 0]].T.float()
    elif env.potential == "euclidean":
        bx, by = env.ix[target] - env.ix[cell], env.iy[target] - env.iy[cell]
        before, after = torch.sqrt(bx * bx + by * by), torch.sqrt(dx * dx + dy * dy)
    else:
        before = after = torch.zeros(())
    return reward_fn(
        env.reward_name,
        d2_after=dx * dx + dy * dy,
        pot_before=before,
        pot_after=after,
        collision=collided.float(),
        reached=(nxt == target).float(),
        diag2=env.mdp.diag2,
    ).float()


class DynaLearner(QLearner):
    """Q-learning's table plus the model, hindsight and planning of the module docstring."""

    def __init__(self, cfg: DynaConfig, env: BatchedNavEnv, gen: torch.Generator):
        super().__init__(cfg, env, gen)
        cells = env.mdp.num_cells
        #: ``long[cells, 4]``: the next believed cell after each action from each believed cell (-1: not tried yet)
        self.model_next = torch.full((cells, 4), -1, dtype=torch.long)
        #: ``bool[cells, 4]``: whether that move collided
        self.model_collided = torch.zeros((cells, 4), dtype=torch.bool)
        self.all_rows = torch.arange(env.pool.numel())
        self.planned = 0

    def observe(self, b, g, a, reward, b_next, collided, terminal, env_steps: int) -> None:
        cfg, lr = self.cfg, learning_rate(self.cfg, env_steps)
        # the model: the last outcome of each (believed cell, action) this batch tried
        keep = first_of_each(b * 4 + a)
        self.model_next[b[keep], a[keep]] = b_next[keep]
        self.model_collided[b[keep], a[keep]] = collided[keep]
        if cfg.hindsight:  # every training target learns from each distinct move
            self.updates += self.update(b[keep], a[keep], b_next[keep], collided[keep], self.all_rows, lr)
        else:
            self.updates += td_update(self.q, b, g, a, reward, b_next, terminal, cfg.gamma, lr)
        known = torch.nonzero(self.model_next.reshape(-1) >= 0, as_tuple=True)[0]
        for _ in range(cfg.planning_steps):
            key = known[torch.randint(known.numel(), (cfg.planning_batch,), generator=self.gen)]
            key = key[first_of_each(key)]
            pb, pa = key // 4, key % 4
            rows = self.all_rows
            if cfg.planning_targets and cfg.planning_targets < rows.numel():
                rows = torch.randperm(rows.numel(), generator=self.gen)[: cfg.planning_targets]
            self.planned += self.update(pb, pa, self.model_next[pb, pa], self.model_collided[pb, pa], rows, lr)

    def update(self, b, a, b_next, collided, rows, lr: float) -> int:
        """Q-learning updates of ``Q[b, g, a]`` for the distinct entries ``(b, a)`` and every target ``g`` of the
        pool rows ``rows``, from the outcome ``(b_next, collided)`` and the reward function; returns how many."""
        target = self.env.pool[rows][None, :]  # [1, k]
        reward = rewards_for(self.env, b, b_next, collided, rows)  # [m, k]
        bb, aa = b[:, None], a[:, None]
        nxt_v = self.q[b_next[:, None], target].max(-1).values  # [m, k]
        current = self.q[bb, target, aa]
        new = current + lr * (reward + self.cfg.gamma * (b_next[:, None] != target).float() * nxt_v - current)
        self.q[bb, target, aa] = torch.where(bb == target, current, new)
        return int(b.numel() * rows.numel())

    def stats(self) -> dict[str, Any]:
        return {
            "updates": self.updates,
            "planned_updates": self.planned,
            "model_entries": int((self.model_next >= 0).sum()),
        }


def learn(
    cfg: DynaConfig,
    dataset: Dataset | None = None,
    *,
    normalizer: Normalizer | None = None,
    callback: Callable[[torch.Tensor, int, float], bool] | None = None,
) -> TabularResult:
    """Dyna-Q on ``dataset`` (default: load ``cfg.dataset_name``); see :func:`dtradar_rl.tabular.qlearning.run`."""
    return run(cfg, DynaLearner, dataset, normalizer=normalizer, callback=callback)


__all__ = ["DynaConfig", "DynaLearner", "learn", "rewards_for"]
