"""The task: a twin's per-cell table as a grid MDP (a moving twin's as one in time) and its rewards, what a robot
observes, start/target pairs, the base config, where runs go. Everything above (envs, agents, trainers) builds on
these."""

from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.grid_mdp import ACTIONS, GridMDP, MovingGridMDP
from dtradar_rl.task.observations import OBS_PRESETS, Normalizer, build_observations
from dtradar_rl.task.rewards import REWARDS
from dtradar_rl.task.twins import load_dataset

__all__ = [
    "ACTIONS",
    "OBS_PRESETS",
    "REWARDS",
    "ConfigError",
    "GridMDP",
    "MovingGridMDP",
    "Normalizer",
    "TwinConfig",
    "build_observations",
    "load_dataset",
]
