"""How the classical planner reads an honest observation (:mod:`dtradar_rl.task.sensing`): one-shot localisation.

The planner keeps no belief: at every step it takes the map cell that best explains what the robot senses now (the
radio filter's likelihood of :class:`~dtradar_rl.agents.radio_filter.RadioFilterAgent` without its prediction
step: every transmitter's measured radio against each cell's fingerprint, the heard flags and the proximity
sensor), the target's cell from its map coordinates, the neighbours the proximity sensor reports blocked, and a
collision from the odometry (a move that did not move the robot).
"""

from __future__ import annotations

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent
from dtradar_rl.task.sensing import PER_TX


class HonestReader:
    """The planner's reading of honest observations on the map of ``blueprint``."""

    def __init__(self, blueprint: Dataset, sensing: str, device: str | torch.device = "cpu"):
        self.model = RadioFilterAgent(blueprint, FilterConfig(scene=blueprint.name, sensing=sensing), str(device))
        self.k = self.model.k

    def env_for(self, ds: Dataset, num_envs: int, **kwargs):
        return self.model.env_for(ds, num_envs, **kwargs)

    def read(self, obs: torch.Tensor, last_action: torch.Tensor):
        """``(fingerprint, cell, target, occupied, stuck, blank)`` per robot (see the module docstring); ``blank``:
        the robot hears no transmitter after a move (a mover may stand on its cell)."""
        k4 = self.k * PER_TX
        radio = obs[:, :k4].reshape(-1, self.k, PER_TX)
        occupied = obs[:, k4 : k4 + 4] > 0.5
        ll = self.model._log_likelihood(radio[..., :-1], radio[..., -1] > 0.5, occupied)
        cell = (ll + self.model.log_prior).argmax(1)
        target = torch.cdist(obs[:, -2:], self.model.positions).argmin(1)
        fresh = obs[:, k4 + 9] > 0.5
        stuck = (last_action >= 0) & (obs[:, k4 + 4] < 0.5) & ~fresh & obs[:, k4 + 5 : k4 + 9].any(1)
        blank = (radio[..., -1] < 0.5).all(1) & (last_action >= 0) & ~fresh
        return obs[:, :k4], cell, target, occupied, stuck, blank


def honest_reader(blueprint: Dataset, sensing, device) -> HonestReader | None:
    """The reader of an honest ``sensing`` on ``blueprint`` (None for the privileged setting)."""
    from dtradar_rl.task.sensing import sensing_for

    return None if sensing_for(sensing).privileged else HonestReader(blueprint, sensing, device)
