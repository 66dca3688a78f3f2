"""Registration of the gymnasium env under ``dtradar/<scene>-<variant>-v0`` ids, one per built dataset."""

from __future__ import annotations

import gymnasium as gym

from dtradar_data.store.listing import list_datasets

SYNTHETIC_ENV_ID = "dtradar/synthetic-blueprint-v0"


def built_datasets() -> list[str]:
    """Names ``scene/variant`` of the datasets built in the data root."""
    return [entry.name for entry in list_datasets() if entry.built]


def env_id(name: str) -> str:
    """``"cubicle/blueprint"`` -> ``"dtradar/cubicle-blueprint-v0"``."""
    scene, _, variant = name.partition("/")
    return f"dtradar/{scene}-{variant or 'blueprint'}-v0"


def register_dataset_envs(**kwargs) -> list[str]:
    """Register one env id per built dataset, plus ``dtradar/synthetic-{blueprint,dynamic}-v0``; returns the ids.

    ``kwargs`` (``obs``, ``reward``, ...) become the default arguments of every id; ``gym.make`` can override them.
    Datasets are loaded when an env is made, not here. Registering again replaces the ids.
    """
    ids = []
    for name in ["synthetic/blueprint", "synthetic/dynamic", *built_datasets()]:
        eid = env_id(name)
        gym.registry.pop(eid, None)
        gym.register(
            id=eid,
            entry_point="dtradar_rl.envs.nav_env:DtradarNavEnv",
            kwargs={"dataset": name, **kwargs},
            disable_env_checker=True,
        )
        ids.append(eid)
    return ids


__all__ = ["SYNTHETIC_ENV_ID", "built_datasets", "env_id", "register_dataset_envs"]
