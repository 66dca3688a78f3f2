"""The batched env's rules of a move: where each action leads, the wait action, and the movers of a moving twin.

Mixed into :class:`~dtradar_rl.envs.batched.BatchedNavEnv`; the rules themselves are
:mod:`dtradar_rl.task.grid_mdp`'s (:meth:`~dtradar_rl.task.grid_mdp.MovingGridMDP.step_at` is the reference a test
holds both environments to).

The wait action (``wait_action=True``): action :data:`~dtradar_rl.task.grid_mdp.WAIT` = 4 keeps the robot on its
cell. The move tables then get a fifth column (the cell itself, never a collision), so the general step reads a wait
like any move; on a moving twin a wait is never a mover collision (it enters nothing) and is still a mover hit when a
mover walks onto the waiting robot. Its reward is the twin's own reward of a step that ends where it began without a
collision (:mod:`dtradar_rl.task.rewards`). With the option off (the default) the tables are the four-column ones
and every op of a step is the one it was.

The movers' penalty (``mover_penalty``, a training setting): a step with a mover collision or a mover hit is charged
``mover_penalty`` times the reward's collision penalty instead of once (1, the default: as a wall bump, the same
ops). With the shaped rewards one collision costs about what one step off the shortest path does, so an agent may
take a risky move rather than wait or step aside; a larger penalty makes meeting a mover dearer than the time lost
to avoid it. Evaluation counts the events, not the reward, so it reads the same agent either way.
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_rl.task.grid_mdp import ACTIONS, WAIT, GridMDP


class MovesMixin:
    """Where the actions of :class:`~dtradar_rl.envs.batched.BatchedNavEnv` lead (its attributes, its step)."""

    def _init_moves(self, mdp: GridMDP, wait_action: bool, mover_penalty: float = 1.0) -> None:
        """The move tables the general step reads: ``next_cell``/``collides``, with a wait column when asked."""
        #: whether action 4 (stay on the cell) is one of the env's actions
        self.wait_action = bool(wait_action)
        #: the collision penalty of a step that meets a mover, in units of the reward's (module docstring)
        self.mover_penalty = float(mover_penalty)
        #: a moving twin's space-time distance tables, made at the first call of _space_time_shortest_moves
        self._st_dist: torch.Tensor | None = None
        if not self.wait_action:
            self._step_cell, self._step_collides = self.next_cell, self.collides
            return
        cells = np.arange(mdp.num_cells)
        self._step_cell = self._tensor(np.concatenate([mdp.next_cell, cells[:, None]], 1), torch.long)
        self._step_collides = self._tensor(np.pad(mdp.collides, ((0, 0), (0, 1))), torch.bool)

    @property
    def num_actions(self) -> int:
        """The env's actions: the four moves, and the wait with ``wait_action``."""
        return len(ACTIONS) + int(self.wait_action)

    def _moves(self, cell: torch.Tensor, a: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(next cell, wall collision)`` of actions ``a`` from ``cell`` on the static map."""
        return self._step_cell[cell, a], self._step_collides[cell, a]

    def _mover_rules(self, cell, nxt, collision, a):
        """A moving twin's step from ``cell`` towards ``nxt`` (after the static collisions): the next snapshot's
        blocked mask refuses a move into a mover, a mover may walk onto the robot. Returns ``(next cell, collision,
        mover collision, mover hit)`` and advances every robot's snapshot."""
        t1 = self.t_next[self.t]
        now, base = self.t * self.mdp.num_cells, t1 * self.mdp.num_cells
        swap = self.covered[now + nxt] & self.covered[base + cell]  # a mover coming the other way
        mover_collision = (self.covered[base + nxt] | swap) & ~collision
        if self.wait_action:  # a wait enters nothing: what comes onto the robot is a hit, not a collision
            mover_collision &= a != WAIT
        nxt = torch.where(mover_collision, cell, nxt)
        mover_hit = self.covered[base + nxt]
        self.t = t1
        return nxt, collision | mover_collision, mover_collision, mover_hit

    def _space_time_shortest_moves(self) -> torch.Tensor:
        """``bool[num_envs, num_actions]`` on a moving twin: the actions along a shortest path in time from each
        robot's ``(cell, snapshot)`` to its target (the search of :mod:`dtradar_rl.task.space_time` with free
        waiting, whose tables are made for the target pool at the first call). An action is one when it neither
        collides (a wall, an extra obstacle, a mover, a mover coming the other way) nor leaves the robot where a mover
        walks onto it, and its ``(cell, next snapshot)`` is one step closer: the four moves, and the wait with
        ``wait_action``. The extra obstacles are not in the search: a shortest move into one is left out, and a robot
        they leave no shortest move gets an all-false row, as does one on its target."""
        cells = self.mdp.num_cells
        if self._st_dist is None or self._st_dist.shape[0] < self.pool.numel():
            tables = self.mdp.space_time_distances_many(self.pool.cpu().numpy(), "free")  # int32[P, T, cells]
            # int16 rows of t * cells + cell: Dallas Q3's 1 950 targets x 50 snapshots take 0.7 GB, not 1.4
            self._st_dist = self._tensor(tables.reshape(tables.shape[0], -1).astype(np.int16), torch.int16)
        cell = self.cell[:, None].expand(-1, self.num_actions)
        a = torch.arange(self.num_actions, device=self.cell.device).expand_as(cell)
        nxt, collision = self._moves(cell, a)
        if self.aug_obstacles:
            collision = collision | self.extra.gather(1, nxt)
        t = self.t[:, None]
        now, base = t * cells, self.t_next[t] * cells
        swap = self.covered[now + nxt] & self.covered[base + cell]  # a mover coming the other way
        ok = ~collision & ~(self.covered[base + nxt] | swap)  # no collision, and no mover walks onto the robot
        here = self._st_dist[self.tpool[:, None], now + cell].int()
        there = self._st_dist[self.tpool[:, None], base + nxt].int()
        return ok & (there >= 0) & (there == here - 1)

    def _mover_penalised(self, collision, mover_collision, mover_hit) -> torch.Tensor:
        """The collision term of a moving twin's step: 1 for a wall bump, ``mover_penalty`` for meeting a mover
        (bools while it is 1, so the reward's ops are the ones they were)."""
        penalised = collision | mover_hit
        if self.mover_penalty == 1.0:
            return penalised
        met = mover_collision | mover_hit
        return torch.where(met, torch.full_like(penalised, self.mover_penalty, dtype=torch.float32), penalised.float())
