"""The gymnasium environment with honest sensing: one robot that is never told where it is.

Description
    A robot with a radio receiver is switched on at a random free cell of a twin and must reach a target given in
    map coordinates. It observes what its own receiver measures on its cell (every transmitter's angles, delay, gain
    and phase of the strongest path, under a receiver noise model), a proximity sensor, and its own odometry; never
    its position, never another cell's radio (:mod:`dtradar_rl.task.sensing`). The blueprint twin is the map an
    agent may carry (``dtradar_data.load("<scene>/blueprint")``).
Actions
    ``Discrete(4)``: X-, X+, Y-, Y+, one cell per step.
Observations
    ``Box(8 K + 12)`` float32, in the order of :func:`~dtradar_rl.task.sensing.honest_names` (``info["names"]`` after
    ``reset``): per transmitter its 7 measured quantities and a heard flag, the proximity sensor's 4 flags, moved,
    the last move one-hot, switched on, the target's ``x, y`` (m).
Rewards
    ``reward`` as in :mod:`dtradar_rl.task.rewards` (default ``geodesic``: -1 per step plus the drop in breadth-first
    distance, with the paper's bonus and collision penalty).
Episode End
    Terminated when the robot reaches the target; truncated after ``max_steps`` (default ``4 * (nx + ny)``).
Arguments
    ``dataset`` (a name such as ``"cubicle/dynamic"`` or a :class:`~dtradar_data.core.dataset.Dataset`), ``sensing``
    (default ``radio``), ``noise`` (default ``realistic``), ``reward``, ``max_steps``. Registered as
    ``dtradar/<scene>-<variant>-v0`` (and ``-honest-v0``) for every built twin (:mod:`dtradar_rl.envs.registration`).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.envs.nav_env import InvalidActionError, parse_cell
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.sensing import Readings, honest_dim, honest_names, sensing_for
from dtradar_rl.task.twins import load_dataset


class HonestGymEnv(gym.Env):
    """One robot with honest sensing (module docstring)."""

    metadata = {"render_modes": []}

    def __init__(
        self,
        dataset: str | Dataset = "synthetic/blueprint",
        sensing: str = "radio",
        noise: str = "realistic",
        reward: str = "geodesic",
        max_steps: int | None = None,
    ):
        self.ds = load_dataset(dataset) if isinstance(dataset, str) else dataset
        self.sensing = sensing_for(sensing)
        self.noise, self.reward_name, self.max_steps_arg = noise, reward, max_steps
        self.readings = Readings.from_dataset(self.ds)
        self.normalizer = Normalizer.fit(self.ds)
        self.names = honest_names(self.readings.transmitters)
        self.observation_space = spaces.Box(-np.inf, np.inf, (honest_dim(self.readings.transmitters),), np.float32)
        self.action_space = spaces.Discrete(4)
        self.env = self._make(0)

    def _make(self, seed: int) -> HonestNavEnv:
        inner = BatchedNavEnv.from_dataset(
            self.ds,
            1,
            obs="goal",
            normalizer=self.normalizer,
            reward=self.reward_name,
            max_steps=self.max_steps_arg,
            seed=seed,
        )
        return HonestNavEnv(inner, self.readings, self.sensing, self.noise, seed)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.env = self._make(int(seed))
        starts = targets = None
        if options:
            nx, ny = self.ds.shape[1], self.ds.shape[0]
            sx, sy = parse_cell("start", options.get("start"), nx, ny)
            tx, ty = parse_cell("target", options.get("target"), nx, ny)
            starts, targets = [sy * nx + sx], [ty * nx + tx]
        self.env.reset_where(torch.ones(1, dtype=torch.bool), starts=starts, targets=targets)
        return self._obs(), {"names": self.names}

    def step(self, action):
        if not self.action_space.contains(action):
            raise InvalidActionError(f"action {action!r} is not one of 0..3", hint="0: X-, 1: X+, 2: Y-, 3: Y+")
        obs, reward, terminated, truncated, info = self.env.step(torch.tensor([int(action)]))
        out = {"collision": bool(info["collision"][0]), "is_success": bool(info["is_success"][0])}
        return obs[0].numpy(), float(reward[0]), bool(terminated[0]), bool(truncated[0]), out

    def _obs(self) -> np.ndarray:
        return self.env.observe()[0].numpy()
