"""A trained greedy policy: the Q-network and :class:`Policy`, which observes any twin the way it was trained.

The online DQN (:mod:`dtradar_rl.train`) writes checkpoints of them (:mod:`dtradar_rl.agents.checkpoints`) and
loads them back (:func:`dtradar_rl.train.saved_runs.load_policy`); evaluation (:mod:`dtradar_rl.evaluation`) and
the offline baselines (:mod:`dtradar_rl.offline`) act with them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import batched_env
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.observations import PAPER_COLUMNS, RADIO_FEATURES, Normalizer, build_observations

#: Seed of the loop escapes' random moves.
ESCAPE_SEED = 0


class QNetwork(nn.Module):
    """``obs -> [Linear, ReLU] x len(hidden) -> Linear -> n_actions action values`` (4 moves; 5 with the wait)."""

    def __init__(self, in_dim: int, hidden: tuple[int, ...], n_actions: int = 4):
        super().__init__()
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(in_dim, h), nn.ReLU()]
            in_dim = h
        layers.append(nn.Linear(in_dim, n_actions))
        self.net = nn.Sequential(*layers)
        self._link()
        self.register_load_state_dict_post_hook(_relink)  # load_state_dict(assign=True) puts in new Parameters

    def _link(self) -> None:
        # The layers' (weight, bias) Parameters, in order: forward calls F.linear on them directly, the same ops as
        # ``self.net(x)`` bit for bit without six nn.Module calls and attribute look-ups (~13 us of one robot's
        # decision, about as much as the arithmetic).
        self._affine = [(m.weight, m.bias) for m in self.net if isinstance(m, nn.Linear)]

    def _apply(self, fn, recurse=True):  # .to(), .cuda(), .half() may put in new Parameters (torch.__future__)
        module = super()._apply(fn, recurse)
        self._link()
        return module

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        *hidden, (w, b) = self._affine
        for hw, hb in hidden:
            x = F.linear(x, hw, hb).relu_()
        return F.linear(x, w, b)


@dataclass
class Policy:
    """A trained greedy policy and everything needed to observe a twin the way it was trained."""

    q: QNetwork
    config: TwinConfig
    normalizer: Normalizer
    obs_preset: str
    meta: dict[str, Any]
    #: the seeded generator of loop escapes (reset by :meth:`env_for`, so every evaluation repeats)
    escape_gen: torch.Generator | None = None
    #: on a moving twin (set by :meth:`env_for`; None on a static one): the shield also gives way to movers
    mover_guard: Any = None

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions. ``shield=True`` (``neighbors`` preset only) never picks a move into a neighbour that
        the twin shows without radio features from any transmitter (blocked or off the grid), unless every move is
        such.

        Loop escape (agents trained with ``memory_visits`` and ``escape_after`` = k > 0): a robot standing on a
        cell it has already stood on k times this episode (its memory's ``visits_here``) takes a random move
        instead (with the shield, one the shield allows); a greedy policy that deterministic observations lead into a
        cycle would otherwise repeat it until the step limit.

        On a moving twin the shield also gives way to a mover sensed next to the robot
        (:class:`~dtradar_rl.agents.planner.MoverGuard`: the least risky move by
        :func:`~dtradar_rl.agents.planner.predicted_risk`, the Q-values ordering moves of equal risk)."""
        with torch.no_grad():
            allowed = None
            if shield:
                flags = obs[..., self.shield_columns()] > 0.5
                allowed = flags | ~flags.any(-1, keepdim=True)
                if self.wait_action:  # a wait enters no cell: the shield never refuses it
                    allowed = torch.cat([allowed, torch.ones_like(allowed[..., :1])], -1)
            stuck = self._stuck(obs)
            if stuck is not None and bool(stuck.all()):  # every robot escapes: the values are not needed
                return self._escape_moves(obs, allowed)
            q = values = self.q(obs)
            if allowed is not None:
                q = torch.where(allowed, q, torch.full_like(q, -torch.inf))
            action = q.argmax(-1)
            if shield and self.mover_guard is not None:  # it may bump into a wall on purpose: the raw values
                action = self.mover_guard.give_way(obs, values, action)
            if stuck is not None:
                action = torch.where(stuck, self._escape_moves(obs, allowed), action)
        return action

    def _stuck(self, obs: torch.Tensor) -> torch.Tensor | None:
        """``bool[...]``: the robots the loop escape moves at random, or None when there are none (the common
        case, told by one read of the last column: a batch-1 decision pays ~2 us for the escape, not ~6)."""
        k = self.escape_after
        if not k:
            return None
        visits_here = obs.select(-1, -1)  # the last column of a memory agent's observation
        n = visits_here.numel()
        if n == 0 or not (visits_here.item() if n == 1 else float(visits_here.max())) >= k:
            return None
        return visits_here >= k

    def _escape_moves(self, obs: torch.Tensor, allowed: torch.Tensor | None) -> torch.Tensor:
        """One seeded random move per robot: uniform, or with the shield uniform among the ``allowed`` ones (a move,
        never the wait: staying does not leave a loop)."""
        if self.escape_gen is None:
            self.escape_gen = _escape_generator(obs.device)
        if allowed is not None:
            allowed = allowed[..., :4]
        if allowed is None:
            return torch.randint(4, obs.shape[:-1], generator=self.escape_gen, device=obs.device)
        score = torch.rand(allowed.shape, generator=self.escape_gen, device=obs.device)
        return torch.where(allowed, score, -1.0).argmax(-1)

    @property
    def wait_action(self) -> bool:
        """Whether the policy has the fifth action, wait (configs from before the setting: no)."""
        return bool(getattr(self.config, "wait_action", False))

    @property
    def clock(self) -> str:
        """The schedule's phase the policy observes (:mod:`dtradar_rl.task.clock`; older configs: none)."""
        return str(getattr(self.config, "clock", "none"))

    @property
    def escape_after(self) -> int:
        """Earlier stands on a cell after which the policy leaves it at random (0 = never)."""
        if not getattr(self.config, "memory_visits", False):
            return 0
        return int(getattr(self.config, "escape_after", 0))

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
        """A batched env over ``ds`` that observes with this policy's preset and training normaliser (and restarts
        the loop escapes' generator, so the same evaluation gives the same moves)."""
        self.escape_gen = None
        self.mover_guard = None
        if ds.is_moving and self.obs_preset == "neighbors":
            from dtradar_rl.agents.planner import MoverGuard  # the planner imports the envs this module does

            self.mover_guard = MoverGuard(ds, self.normalizer, kwargs.get("device", "cpu"))
        return batched_env(
            ds,
            num_envs,
            memory_radius=getattr(self.config, "memory_radius", 0),
            memory_bumps=getattr(self.config, "memory_bumps", False),
            memory_visits=getattr(self.config, "memory_visits", False),
            obs=self.obs_preset,
            sense_radius=self.sense_radius,
            clock=self.clock,
            wait_action=self.wait_action,
            normalizer=self.normalizer,
            **kwargs,
        )

    @property
    def sense_radius(self) -> int:
        """Cells the policy senses around the robot (1: its four neighbours; configs from before the setting: 1)."""
        return int(getattr(self.config, "sense_radius", 1))

    def observations(self, ds: Dataset):
        return build_observations(ds, self.obs_preset, self.normalizer, self.sense_radius, self.clock)


def _relink(module: QNetwork, _incompatible_keys) -> None:
    module._link()


def _escape_generator(device: torch.device) -> torch.Generator:
    gen = torch.Generator(device=device)
    gen.manual_seed(ESCAPE_SEED)
    return gen
