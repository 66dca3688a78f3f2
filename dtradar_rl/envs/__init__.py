"""Environments over a twin's table: the gymnasium env (one robot) and its registration, the batched torch env
(many robots, obstacle augmentation), the memory env of the memory agents, and honest sensing over them.

Importing this package registers the gymnasium ids of every built twin (``dtradar/<scene>-<variant>-v0`` and
``dtradar/<scene>-<variant>-honest-v0``; :func:`register_dataset_envs`), so gymnasium's own form works in a fresh
process: ``gym.make("dtradar_rl.envs:dtradar/cubicle-blueprint-honest-v0")``. A data root that cannot be listed
registers the synthetic ids only; :func:`register_dataset_envs` called directly says what is wrong."""

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import MemoryNavEnv, batched_env
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.envs.registration import register_dataset_envs, register_on_import

__all__ = ["BatchedNavEnv", "DtradarNavEnv", "MemoryNavEnv", "batched_env", "register_dataset_envs"]

register_on_import()
