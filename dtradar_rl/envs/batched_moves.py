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
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_rl.task.grid_mdp import ACTIONS, WAIT, GridMDP


class MovesMixin:
    """Where the actions of :class:`~dtradar_rl.envs.batched.BatchedNavEnv` lead (its attributes, its step)."""

    def _init_moves(self, mdp: GridMDP, wait_action: bool) -> None:
        """The move tables the general step reads: ``next_cell``/``collides``, with a wait column when asked."""
        #: whether action 4 (stay on the cell) is one of the env's actions
        self.wait_action = bool(wait_action)
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
