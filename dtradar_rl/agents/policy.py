"""A trained greedy policy: the Q-network and :class:`Policy`, which observes any twin the way it was trained.

The online DQN (:mod:`dtradar_rl.train`) writes checkpoints of them (:mod:`dtradar_rl.agents.checkpoints`) and
loads them back (:func:`dtradar_rl.train.checkpoints.load_policy`); evaluation (:mod:`dtradar_rl.evaluation`) and
the offline baselines (:mod:`dtradar_rl.offline`) act with them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import batched_env
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.observations import PAPER_COLUMNS, RADIO_FEATURES, Normalizer, build_observations


class QNetwork(nn.Module):
    """``obs -> [Linear, ReLU] x len(hidden) -> Linear -> 4 action values``."""

    def __init__(self, in_dim: int, hidden: tuple[int, ...], n_actions: int = 4):
        super().__init__()
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(in_dim, h), nn.ReLU()]
            in_dim = h
        layers.append(nn.Linear(in_dim, n_actions))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


@dataclass
class Policy:
    """A trained greedy policy and everything needed to observe a twin the way it was trained."""

    q: QNetwork
    config: TwinConfig
    normalizer: Normalizer
    obs_preset: str
    meta: dict[str, Any]

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions. ``shield=True`` (``neighbors`` preset only) never picks a move into a neighbour that
        the twin shows without radio features (blocked or off the grid), unless every move is such."""
        with torch.no_grad():
            q = self.q(obs)
            if shield:
                flags = obs[..., self.shield_columns()] > 0.5
                q = torch.where(flags | ~flags.any(-1, keepdim=True), q, torch.full_like(q, -torch.inf))
            return q.argmax(-1)

    def shield_columns(self) -> list[int]:
        """Observation columns of the four has-radio flags (``neighbors`` preset), in action order."""
        if self.obs_preset != "neighbors":
            raise ConfigError(
                f"the obstacle shield needs the 'neighbors' observation preset, "
                f"this policy observes {self.obs_preset!r}"
            )
        k = len(RADIO_FEATURES) + 1
        return [len(PAPER_COLUMNS) + a * k + k - 1 for a in range(4)]

    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        """A batched env over ``ds`` that observes with this policy's preset and training normaliser."""
        return batched_env(
            ds,
            num_envs,
            memory_radius=getattr(self.config, "memory_radius", 0),
            memory_bumps=getattr(self.config, "memory_bumps", False),
            obs=self.obs_preset,
            normalizer=self.normalizer,
            **kwargs,
        )

    def observations(self, ds: Dataset):
        return build_observations(ds, self.obs_preset, self.normalizer)
