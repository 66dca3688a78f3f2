"""The envs a Minari copy of a logged dataset records, so ``recover_environment()`` gives the logging env and
``recover_environment(eval_env=True)`` the evaluation env (the dynamic twin of a blueprint log).

A copy with ``senses="memory"`` (``<id>-memory``) holds every step as the default online agent observes it (the
logged observation with its memory window, rebuilt exactly from the log: :mod:`dtradar_rl.offline.memory_senses`),
and its envs are the memory env (:class:`~dtradar_rl.envs.memory.MemoryGymEnv`) with the same settings
(:data:`MINARI_MEMORY`), so an agent trained on it is evaluated with the senses it learned from."""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.errors import DtradarError, SchemaMismatchError, unknown_name
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.envs.registration import honest_env_spec, twin_env_spec, twin_version
from dtradar_rl.offline.config import MEMORY_SETTINGS
from dtradar_rl.task.sensing import HONEST_PRESET
from dtradar_rl.task.twins import load_dataset


@dataclass
class MinariEnvs:
    """The envs a Minari copy records (:func:`minari_envs`): the logging env, made (its spaces are the copy's), its
    spec and the evaluation env's spec; or, when they cannot be made, None and why (``retry``: the twin was not
    here, so a later export tries again)."""

    env: Any = None
    spec: Any = None
    eval_spec: Any = None
    missing: str = ""
    retry: bool = False
    arrays: dict[str, np.ndarray] | None = None
    """The log's arrays as the copy holds them (``senses="memory"``: the window appended); None: the log's own."""

    def record(self) -> dict[str, Any]:
        """Their part of ``dtradar.json``."""
        return {
            "env_spec": json.loads(self.spec.to_json()) if self.spec is not None else None,
            "eval_env_spec": json.loads(self.eval_spec.to_json()) if self.eval_spec is not None else None,
            "env_missing": self.missing or None,
            "env_retry": self.retry,
        }


#: The memory settings of a ``senses="memory"`` copy: the default agent's window (radius 5, visit counts, no bumps),
#: as offline training uses it (:data:`~dtradar_rl.offline.config.MEMORY_SETTINGS`, less the policy's loop escape).
MINARI_MEMORY = {k: v for k, v in MEMORY_SETTINGS.items() if k.startswith("memory_")}
SENSES = ("none", "memory")


def check_senses(senses: str) -> str:
    if senses not in SENSES:
        raise unknown_name("Minari copy senses", senses, SENSES)
    return senses


def minari_suffix(senses: str) -> str:
    """What a copy's Minari id adds before ``-v<N>``: ``-memory`` for a memory copy."""
    return "" if check_senses(senses) == "none" else f"-{senses}"


def minari_env_specs(logged: LoggedDataset, senses: str = "none"):
    """``(spec, eval_spec)``: the gymnasium env specs of ``logged``'s Minari copy, from its ``meta.json`` (and which
    dynamic twin is here).

    ``spec`` (``recover_environment()``): the navigation env on the twin the data was logged on, pinned to its
    version (``dataset``/``version``: ``meta.parent``/``meta.parent_version``), with the logged observation preset,
    reward, step limit, the logged feature normaliser and no noise (logged steps are noise-free, and memoryless: a
    memory agent cannot log). ``eval_spec`` (``recover_environment(eval_env=True)``): for a log on a ``blueprint``
    twin, the same settings on the scene's ``dynamic`` twin (its newest version here, pinned; the training twin's
    normaliser, as every evaluation of a policy on another twin: the transfer test of DT-RaDaR), when that twin
    is here; otherwise (a log on the dynamic twin, or no dynamic twin here) ``spec`` itself. A meta that lacks
    what the spec needs is a :class:`SchemaMismatchError`; a missing dynamic twin is no error. ``senses="memory"``:
    both are the memory env (:data:`MINARI_MEMORY`)."""
    meta = logged.meta
    settings = meta.get("settings") or {}
    preset = (meta.get("observations") or {}).get("preset")
    parent, version = meta.get("parent"), meta.get("parent_version")
    lacking = [
        k
        for k, v in {
            "parent": parent,
            "parent_version": version,
            "observations.preset": preset,
            "normalizer": meta.get("normalizer"),
            "settings.reward": settings.get("reward"),
            "settings.max_steps": settings.get("max_steps"),
        }.items()
        if not v
    ]
    if lacking:
        raise SchemaMismatchError(
            f"{logged.name}@{logged.version}: its meta.json lacks {', '.join(lacking)} (not logged by log_dataset)",
            hint="log it again with `python -m dtradar_rl log ...` to give its Minari copy an env spec",
        )
    obs_meta = meta.get("observations") or {}
    if preset == HONEST_PRESET:  # what the robot's own sensors read: the honest-sensing env, same sensing and noise
        if senses == "memory":
            raise SchemaMismatchError(
                f"{logged.name} records honest sensing; the memory copy extends the privileged observation",
                hint="export its Minari copy with senses='none'",
            )
        honest_kw = {
            "sensing": str(obs_meta.get("sensing")),
            "noise": str(obs_meta.get("noise", "none")),
            "reward": str(settings["reward"]),
            "max_steps": int(settings["max_steps"]),
        }
        spec = honest_env_spec(str(parent), str(version), **honest_kw)
        scene, _, variant = str(parent).partition("/")
        dynamic = _dynamic_twin(scene) if variant == "blueprint" else None
        eval_spec = spec if dynamic is None else honest_env_spec(f"{scene}/dynamic", twin_version(dynamic), **honest_kw)
        return spec, eval_spec
    settings_kw = {
        "obs": str(preset),
        "reward": str(settings["reward"]),
        "max_steps": int(settings["max_steps"]),
        "normalizer": meta["normalizer"],
        "memory": MINARI_MEMORY if check_senses(senses) == "memory" else None,
    }
    spec = twin_env_spec(str(parent), str(version), **settings_kw)
    eval_spec = spec
    scene, _, variant = str(parent).partition("/")
    dynamic = _dynamic_twin(scene) if variant == "blueprint" else None
    if dynamic is not None:
        eval_spec = twin_env_spec(f"{scene}/dynamic", twin_version(dynamic), **settings_kw)
    return spec, eval_spec


def _dynamic_twin(scene: str):
    """The scene's dynamic twin when it is here (a blueprint log's evaluation twin), else None."""
    try:
        return load_dataset(f"{scene}/dynamic")
    except DtradarError:  # not built or pulled here: evaluate on the logging twin
        return None


def minari_envs(logged: LoggedDataset, senses: str = "none") -> MinariEnvs:
    """The specs of :func:`minari_env_specs` with the logging env made from its spec, checked against the data (its
    observation dimension, and every logged observation inside its observation space); :class:`MinariEnvs` with
    ``missing`` when the meta lacks what a spec needs, or the twin at its version is not here or does not fit."""
    import gymnasium as gym

    try:
        spec, eval_spec = minari_env_specs(logged, senses)
    except SchemaMismatchError as e:
        return MinariEnvs(missing=e.message)
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            env = gym.make(spec)
        a = logged.arrays()
        if senses == "memory":
            from dtradar_rl.offline.memory_senses import MemorySenses

            m = MINARI_MEMORY
            window = MemorySenses(
                logged, env.unwrapped.mdp, radius=m["memory_radius"], bumps=m["memory_bumps"], visits=m["memory_visits"]
            )
            a = window.arrays(a)
        space = env.observation_space
        if space.shape != a["obs"].shape[1:]:
            raise SchemaMismatchError(f"the env observes {space.shape}, the data holds {a['obs'].shape[1:]}")
        for k in ("obs", "next_obs"):
            if not (np.all(a[k] >= space.low) and np.all(a[k] <= space.high)):
                raise SchemaMismatchError(f"logged {k} fall outside the env's observation space")
    except DtradarError as e:
        return MinariEnvs(
            missing=f"twin {_pinned(spec)}: {e.message}",
            retry=not isinstance(e, SchemaMismatchError),
        )
    return MinariEnvs(env, spec, eval_spec, arrays=a)


def _pinned(spec) -> str:
    k = spec.kwargs
    return k["dataset"] if "version" not in k else f"{k['dataset']}@{k['version']}"


def env_text(spec) -> str:
    """A spec in one line, for the card and messages."""
    k = spec.kwargs
    if "sensing" in k:  # the honest-sensing env
        return (
            f"{k['dataset']} (honest sensing {k['sensing']}, receiver noise {k['noise']}, reward {k['reward']}, "
            f"max_steps {k['max_steps']})"
        )
    return (
        f"{k['dataset']}@{k['version']} (obs {k['obs']}, reward {k['reward']}, max_steps {k['max_steps']}, noise "
        f"{k['noise']}" + (f", memory radius {k['memory_radius']}" if k.get("memory_radius") else "") + ")"
    )


__all__ = [
    "MINARI_MEMORY",
    "SENSES",
    "MinariEnvs",
    "check_senses",
    "env_text",
    "minari_env_specs",
    "minari_envs",
    "minari_suffix",
]
