"""Environments over a twin's table: the gymnasium env (one robot) and its registration, the batched torch env
(many robots, obstacle augmentation), the memory env of the memory agents, and honest sensing over them.

Importing this package (``import dtradar_rl`` does) registers the gymnasium ids of every built twin
(``dtradar/<scene>-<variant>-v0``, honest sensing, and beside it ``-honest-v0``, ``-privileged-v0`` and
``-privileged-memory-v0``; :func:`register_dataset_envs`), so ``gym.make("dtradar/cubicle-blueprint-v0")`` works after
``import dtradar_rl``, and gymnasium's own form in a fresh process:
``gym.make("dtradar_rl.envs:dtradar/cubicle-blueprint-v0")``. A data root that cannot be listed registers the
synthetic ids only; :func:`register_dataset_envs` called directly says what is wrong. The env classes load when first
used (torch is not imported by the registration)."""

from importlib import import_module

from dtradar_rl.envs.registration import register_dataset_envs, register_on_import

_LAZY = {
    "BatchedNavEnv": "dtradar_rl.envs.batched",
    "MemoryNavEnv": "dtradar_rl.envs.memory",
    "batched_env": "dtradar_rl.envs.memory",
    "DtradarNavEnv": "dtradar_rl.envs.nav_env",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["BatchedNavEnv", "DtradarNavEnv", "MemoryNavEnv", "batched_env", "register_dataset_envs"]

register_on_import()
