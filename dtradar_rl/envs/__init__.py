"""Environments over a twin's table: the gymnasium env (one robot) and its registration, the batched torch env
(many robots, obstacle augmentation) and the memory env of the memory agents."""

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryNavEnv, batched_env
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.envs.registration import register_dataset_envs

__all__ = ["BatchedNavEnv", "DtradarNavEnv", "MemoryNavEnv", "batched_env", "register_dataset_envs"]
