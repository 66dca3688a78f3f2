"""Honest sensing for the batched environment: what a robot with a radio receiver observes, nothing more.

:class:`HonestNavEnv` plays the episodes of a :class:`~dtradar_rl.envs.batched.BatchedNavEnv` (the same moves,
collisions, movers, rewards and seeded pairs) and replaces its observation by the honest one of
:mod:`dtradar_rl.task.sensing`: the robot's own cell's radio as its receiver measures it (a
:class:`~dtradar_rl.task.noise.NoiseModel`'s errors drawn per robot, transmitter and step, azimuths and phase wrapped
on the circle), the proximity sensor, its odometry (its last move and whether it moved) and the target on the map. The
inner env's own observation (position, neighbours' radio) is never read: :meth:`observe` looks up
:class:`~dtradar_rl.task.sensing.Readings` by the robot's cell, and each row of those tables holds that cell's own
readings only.

Agents that act from honest sensing (:class:`~dtradar_rl.agents.radio_filter.RadioFilterAgent`, the planner with
``sensing="radio"``) make their envs here; everything else an evaluation reads (``cell``, ``mdp``, ``steps``...) is the
inner env's, for the scorer, never for the agent.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.task.noise import NOISE_SEED_OFFSET, NoiseModel, noise_model
from dtradar_rl.task.sensing import CIRCULAR, PER_TX, Readings, Sensing, honest_dim, sensing_for


class HonestNavEnv:
    """Episodes of a batched env observed through an honest :class:`~dtradar_rl.task.sensing.Sensing`."""

    def __init__(
        self, inner: BatchedNavEnv, readings: Readings, sensing: str | Sensing = "radio", noise="none", seed: int = 0
    ):
        self.inner, self.sensing = inner, sensing_for(sensing)
        if self.sensing.privileged:
            raise ValueError("HonestNavEnv observes honestly; the privileged setting is the learnt agents' presets")
        dev = self.device = inner.device
        t = lambda a, dt=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=dev)
        measured = self.sensing.measured
        self.radio = t(readings.radio * measured[None, None, :])  # [rows, K, 7]; a group left out reads 0
        # whether the receiver hears each transmitter is radio too: with no radio at all the receiver is off
        self.heard = t(readings.heard if self.sensing.groups else np.zeros_like(readings.heard), torch.float32)
        self.around = t(readings.blocked_around if self.sensing.proximity else np.zeros_like(readings.blocked_around))
        self.target_xy = t(readings.target_xy)
        self.transmitters = readings.transmitters
        self.model: NoiseModel = noise_model(noise)
        self.sigma = t(self.model.sigmas() * measured)  # [7]
        self.circular = t(CIRCULAR, torch.bool)
        self.gen = torch.Generator(device=dev)
        self.gen.manual_seed(int(seed) + NOISE_SEED_OFFSET)
        n = inner.num_envs
        self.moved = torch.zeros(n, device=dev)
        self.last = torch.full((n,), -1, dtype=torch.long, device=dev)
        self.fresh = torch.ones(n, device=dev)
        self.errors = torch.zeros((n, self.transmitters, 7), device=dev)
        self._draw()

    @classmethod
    def from_dataset(
        cls, ds: Dataset, num_envs: int, *, sensing="radio", noise="none", seed: int = 0, **kwargs
    ) -> HonestNavEnv:
        """The honest env of ``ds``; ``kwargs`` go to the inner :class:`BatchedNavEnv` (reward, max_steps, device...).
        Its observation preset is ``goal`` with the twin's own statistics: nothing of it reaches the robot."""
        inner = BatchedNavEnv.from_dataset(ds, num_envs, obs="goal", seed=seed, **kwargs)
        return cls(inner, Readings.from_dataset(ds), sensing, noise, seed)

    def __getattr__(self, name):  # cell, target, mdp, steps, num_envs, max_steps...: the inner env's
        return getattr(self.inner, name)

    @property
    def obs_dim(self) -> int:
        return honest_dim(self.transmitters)

    def _rows(self) -> torch.Tensor:
        return self.inner._rows()

    def _draw(self, idx: torch.Tensor | None = None) -> None:
        """New receiver errors for every robot (or those in ``idx``): one draw per transmitter and quantity."""
        if self.model.is_zero:
            return
        k = self.inner.num_envs if idx is None else idx.numel()
        e = torch.randn((k, self.transmitters, 7), generator=self.gen, device=self.device) * self.sigma
        if idx is None:
            self.errors = e
        else:
            self.errors[idx] = e

    def observe(self) -> torch.Tensor:
        """``float32[num_envs, obs_dim]``: the honest observations (:mod:`dtradar_rl.task.sensing`)."""
        rows = self._rows()
        heard = self.heard.index_select(0, rows)  # [n, K]
        radio = self.radio.index_select(0, rows)
        if not self.model.is_zero:
            radio = radio + self.errors
            wrapped = torch.remainder(radio + math.pi, 2 * math.pi) - math.pi
            radio = torch.where(self.circular, wrapped, radio)
        radio = radio * heard[..., None]  # a transmitter not heard reads 0, noise included
        n = rows.numel()
        last = torch.zeros((n, 4), device=self.device)
        has_last = self.last >= 0
        last[has_last, self.last[has_last]] = 1.0
        per_tx = torch.cat([radio, heard[..., None]], 2).reshape(n, self.transmitters * PER_TX)
        tail = [self.around.index_select(0, rows), self.moved[:, None], last, self.fresh[:, None]]
        return torch.cat([per_tx, *tail, self.target_xy.index_select(0, self.inner.target)], 1)

    def reset(self) -> torch.Tensor:
        self.reset_where(torch.ones(self.inner.num_envs, dtype=torch.bool, device=self.device))
        return self.observe()

    def reset_where(self, mask: torch.Tensor, starts=None, targets=None, t0=None) -> None:
        """New episodes where ``mask`` holds (see :meth:`BatchedNavEnv.reset_where`): the robots are switched on."""
        self.inner.reset_where(mask, starts=starts, targets=targets, t0=t0)
        self.switched_on(mask)

    def switched_on(self, mask: torch.Tensor) -> None:
        """The robots where ``mask`` holds start new episodes of the inner env (reset there by whoever started them,
        e.g. a logger's walk): their next observation is a switched-on robot's, with no odometry yet."""
        idx = torch.nonzero(mask.to(self.device), as_tuple=True)[0]
        self.fresh[idx], self.moved[idx], self.last[idx] = 1.0, 0.0, -1
        self._draw(idx)

    def step(self, actions: torch.Tensor):
        """The inner env's step; the observation is the honest one after it (odometry: this move and whether the
        robot moved)."""
        before = self.inner.cell.clone()
        a = actions.to(self.device, torch.long)
        _, reward, terminated, truncated, info = self.inner.step(a)
        self.moved = (self.inner.cell != before).float()
        self.last = torch.where(a < 4, a, torch.full_like(a, -1))  # a wait is no move
        self.fresh = torch.zeros_like(self.fresh)
        self._draw()
        return self.observe(), reward, terminated, truncated, info
