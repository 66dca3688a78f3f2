"""Registration of the gymnasium ids, four per built dataset, and the env specs that pin a twin version
(:func:`twin_env_spec`, recorded by every Minari copy of a logged dataset).

``dtradar/<scene>-<variant>-v0`` is what the default agent observes: honest sensing (its own cell's radio under
receiver noise, proximity, odometry, the target on the map; never its position). ``-honest-v0`` is the same env named
by its sensing. The learnt agents' observations hold the robot's position, so their ids say so:
``-privileged-v0`` (an observation preset, ``goal`` by default) and ``-privileged-memory-v0`` (the default learnt
agent's: ``neighbors`` with its memory window). ``import dtradar_rl`` registers them, as gymnasium's own packages do.

A pinned spec needs no registration: its entry point :data:`TWIN_ENTRY_POINT` is a ``"module:function"`` string that
gymnasium imports itself, so ``gym.make(spec)`` (and Minari's ``recover_environment()``) works in a fresh process
that never imported dtradar_rl.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.store import list_datasets
from dtradar_data.store.logged import table_digest

SYNTHETIC_ENV_ID = "dtradar/synthetic-blueprint-v0"
#: The entry point of :func:`twin_env_spec`'s specs: :func:`make_twin_env`, imported by gymnasium from this string.
TWIN_ENTRY_POINT = "dtradar_rl.envs.registration:make_twin_env"


def built_datasets() -> list[str]:
    """Names ``scene/variant`` of the datasets built in the data root."""
    return [entry.name for entry in list_datasets() if entry.built]


def env_id(name: str) -> str:
    """``"cubicle/blueprint"`` -> ``"dtradar/cubicle-blueprint-v0"``: what the default agent observes (honest)."""
    scene, _, variant = name.partition("/")
    return f"dtradar/{scene}-{variant or 'blueprint'}-v0"


def _suffixed(name: str, suffix: str) -> str:
    return env_id(name)[: -len("-v0")] + f"-{suffix}-v0"


def honest_env_id(name: str) -> str:
    """``"cubicle/blueprint"`` -> ``"dtradar/cubicle-blueprint-honest-v0"``: the same env as :func:`env_id`, named
    by its sensing."""
    return _suffixed(name, "honest")


def privileged_env_id(name: str) -> str:
    """``"cubicle/blueprint"`` -> ``"dtradar/cubicle-blueprint-privileged-v0"``: a learnt agent's observation preset,
    which holds the robot's position (:class:`~dtradar_rl.envs.nav_env.DtradarNavEnv`)."""
    return _suffixed(name, "privileged")


def memory_env_id(name: str) -> str:
    """``"cubicle/blueprint"`` -> ``"dtradar/cubicle-blueprint-privileged-memory-v0"``: the default learnt agent's
    observation, ``neighbors`` and its memory window (:class:`~dtradar_rl.envs.memory.MemoryGymEnv`)."""
    return _suffixed(name, "privileged-memory")


#: The memory id's settings: the default learnt agent's (``make train AGENT=dqn``; dtradar_rl.train.config).
MEMORY_DEFAULTS: dict[str, Any] = {
    "obs": "neighbors",
    "reward": "geodesic",
    "memory_radius": 5,
    "memory_visits": True,
    "memory_bumps": False,
}


def register_dataset_envs(**kwargs) -> list[str]:
    """Register the four ids of every built dataset and of ``synthetic/blueprint``, ``synthetic/dynamic`` and the
    moving ``synthetic-moving/blueprint`` (module docstring); returns the ids.

    ``kwargs`` (``obs``, ``reward``, ...) become the default arguments of every ``-privileged-v0`` id; ``gym.make``
    can override them, and the honest ids' (``sensing``, ``noise``, ``reward``, ``max_steps``). Datasets are loaded
    when an env is made, not here. Registering again replaces the ids.
    """
    return _register(
        ["synthetic/blueprint", "synthetic/dynamic", "synthetic-moving/blueprint", *built_datasets()], kwargs
    )


def _register(names: list[str], kwargs: dict) -> list[str]:
    ids = []
    for name in names:
        entries = {
            env_id(name): ("dtradar_rl.envs.honest_gym:HonestGymEnv", {"dataset": name}),
            honest_env_id(name): ("dtradar_rl.envs.honest_gym:HonestGymEnv", {"dataset": name}),
            privileged_env_id(name): ("dtradar_rl.envs.nav_env:DtradarNavEnv", {"dataset": name, **kwargs}),
            memory_env_id(name): (TWIN_ENTRY_POINT, {"dataset": name, **MEMORY_DEFAULTS}),
        }
        for eid, (entry_point, kw) in entries.items():
            gym.registry.pop(eid, None)
            gym.register(id=eid, entry_point=entry_point, kwargs=kw, disable_env_checker=True)
            ids.append(eid)
    return ids


def register_on_import() -> list[str]:
    """:func:`register_dataset_envs` as importing :mod:`dtradar_rl.envs` does it: a data root that cannot be listed
    (missing, unreadable, damaged) registers the synthetic twins' ids alone rather than failing the import."""
    from dtradar_data.core.errors import DtradarError

    try:
        return register_dataset_envs()
    except (DtradarError, OSError):
        return _register(["synthetic/blueprint", "synthetic/dynamic", "synthetic-moving/blueprint"], {})


def twin_version(ds: Dataset) -> str:
    """The content version that pins a twin: its stored version, or a hash of its table for a twin without one
    (synthetic twins; the same value a logged dataset records as ``parent_version``)."""
    return ds.version or table_digest(ds.table)


def make_twin_env(dataset: str, version: str | None = None, **kwargs: Any) -> gym.Env:
    """:class:`~dtradar_rl.envs.nav_env.DtradarNavEnv` on twin ``dataset`` (``"cubicle/blueprint"``) at content
    ``version`` (:func:`twin_version`; None: the newest). A stored twin is loaded at that version (a missing one is a
    ``DatasetNotFoundError``/``RevisionNotFoundError`` saying how to build or pull it); a synthetic twin is generated
    and its table hash checked (another is a :class:`SchemaMismatchError`: this dtradar generates another table).
    ``kwargs`` are the env's (``obs``, ``reward``, ``max_steps``, ``normalizer``, ``noise``, ``render_mode``); with
    ``memory_radius`` > 0 (and ``memory_visits``, ``memory_bumps``) it is the memory env
    (:class:`~dtradar_rl.envs.memory.MemoryGymEnv`: the default agent's senses)."""
    from dtradar_rl.envs.nav_env import DtradarNavEnv
    from dtradar_rl.task.twins import is_synthetic, load_dataset

    scene = dataset.partition("/")[0]
    if "@" in dataset:
        raise SchemaMismatchError(
            f"make_twin_env: give the twin as a name and its version apart, not {dataset!r}",
            hint="dataset='<scene>/<variant>', version='<version>'",
        )
    ds = load_dataset(dataset if version is None or is_synthetic(scene) else f"{dataset}@{version}")
    got = twin_version(ds)
    if version is not None and got != version:
        raise SchemaMismatchError(
            f"twin {dataset} is version {got} here, the env spec pins {version}",
            hint="use the dtradar release that logged the data (synthetic twins are generated by the code), or pass "
            "version=None to gym.make to run on this one",
        )
    if kwargs.get("memory_radius"):
        from dtradar_rl.envs.memory import MemoryGymEnv

        return MemoryGymEnv(ds, **kwargs)
    for k in ("memory_radius", "memory_visits", "memory_bumps"):  # a memoryless spec may name them off
        kwargs.pop(k, None)
    return DtradarNavEnv(ds, **kwargs)


def twin_env_spec(
    dataset: str,
    version: str | None,
    *,
    obs: str,
    reward: str,
    max_steps: int,
    normalizer: dict[str, Any] | None = None,
    noise: str = "none",
    memory: dict[str, Any] | None = None,
) -> EnvSpec:
    """The spec of a learnt agent's env on ``dataset`` pinned to ``version``, id :func:`privileged_env_id` (or
    :func:`memory_env_id` with ``memory``; ``gym.make(spec)``
    needs no registration; ``gym.make(spec, **kw)`` overrides a setting). No ``max_episode_steps``: the env
    truncates at ``max_steps`` itself (gymnasium's ``TimeLimit`` would also flag the step that reaches the target
    on the last step as truncated, which the env and the logged data do not). ``memory`` (``memory_radius``,
    ``memory_visits``, ``memory_bumps``) makes it the memory env; None, the memoryless one (and the spec of old)."""
    kwargs: dict[str, Any] = {
        "dataset": dataset,
        "version": version,
        "obs": obs,
        "reward": reward,
        "max_steps": int(max_steps),
        "normalizer": normalizer,
        "noise": noise,
        **(memory or {}),
    }
    return EnvSpec(
        id=memory_env_id(dataset) if (memory or {}).get("memory_radius") else privileged_env_id(dataset),
        entry_point=TWIN_ENTRY_POINT,
        max_episode_steps=None,
        disable_env_checker=True,
        kwargs=kwargs,
    )


def honest_env_spec(
    dataset: str, version: str | None, *, sensing: str, noise: str, reward: str, max_steps: int
) -> EnvSpec:
    """The spec of the honest-sensing env (:class:`~dtradar_rl.envs.honest_gym.HonestGymEnv`) on ``dataset`` pinned
    to ``version``, id :func:`honest_env_id`: what an honest logged dataset's Minari copy records."""
    kwargs = {
        "dataset": f"{dataset}@{version}" if version else dataset,
        "sensing": sensing,
        "noise": noise,
        "reward": reward,
        "max_steps": int(max_steps),
    }
    return EnvSpec(
        id=honest_env_id(dataset),
        entry_point="dtradar_rl.envs.honest_gym:HonestGymEnv",
        max_episode_steps=None,
        disable_env_checker=True,
        kwargs=kwargs,
    )


__all__ = [
    "MEMORY_DEFAULTS",
    "SYNTHETIC_ENV_ID",
    "TWIN_ENTRY_POINT",
    "built_datasets",
    "env_id",
    "make_twin_env",
    "honest_env_id",
    "honest_env_spec",
    "memory_env_id",
    "privileged_env_id",
    "register_dataset_envs",
    "twin_env_spec",
    "twin_version",
]
