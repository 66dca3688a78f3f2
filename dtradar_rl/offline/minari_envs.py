"""The envs a Minari copy of a logged dataset records, so ``recover_environment()`` gives the logging env and
``recover_environment(eval_env=True)`` the evaluation env (the dynamic twin of a blueprint log)."""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.errors import DtradarError, SchemaMismatchError
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.envs.registration import twin_env_spec, twin_version
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

    def record(self) -> dict[str, Any]:
        """Their part of ``dtradar.json``."""
        return {
            "env_spec": json.loads(self.spec.to_json()) if self.spec is not None else None,
            "eval_env_spec": json.loads(self.eval_spec.to_json()) if self.eval_spec is not None else None,
            "env_missing": self.missing or None,
            "env_retry": self.retry,
        }


def minari_env_specs(logged: LoggedDataset):
    """``(spec, eval_spec)``: the gymnasium env specs of ``logged``'s Minari copy, from its ``meta.json`` (and which
    dynamic twin is here).

    ``spec`` (``recover_environment()``): the navigation env on the twin the data was logged on, pinned to its
    version (``dataset``/``version``: ``meta.parent``/``meta.parent_version``), with the logged observation preset,
    reward, step limit, the logged feature normaliser and no noise (logged steps are noise-free, and memoryless: a
    memory agent cannot log). ``eval_spec`` (``recover_environment(eval_env=True)``): for a log on a ``blueprint``
    twin, the same settings on the scene's ``dynamic`` twin (its newest version here, pinned; the training twin's
    normaliser, as every evaluation of a policy on another twin: the transfer test of DT-RaDaR), when that twin
    is here; otherwise (a log on the dynamic twin, or no dynamic twin here) ``spec`` itself. A meta that lacks
    what the spec needs is a :class:`SchemaMismatchError`; a missing dynamic twin is no error."""
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
    settings_kw = {
        "obs": str(preset),
        "reward": str(settings["reward"]),
        "max_steps": int(settings["max_steps"]),
        "normalizer": meta["normalizer"],
    }
    spec = twin_env_spec(str(parent), str(version), **settings_kw)
    eval_spec = spec
    scene, _, variant = str(parent).partition("/")
    if variant == "blueprint":
        try:
            dynamic = load_dataset(f"{scene}/dynamic")
        except DtradarError:  # not built or pulled here: evaluate on the logging twin
            dynamic = None
        if dynamic is not None:
            eval_spec = twin_env_spec(f"{scene}/dynamic", twin_version(dynamic), **settings_kw)
    return spec, eval_spec


def minari_envs(logged: LoggedDataset) -> MinariEnvs:
    """The specs of :func:`minari_env_specs` with the logging env made from its spec, checked against the data (its
    observation dimension, and every logged observation inside its observation space); :class:`MinariEnvs` with
    ``missing`` when the meta lacks what a spec needs, or the twin at its version is not here or does not fit."""
    import gymnasium as gym

    try:
        spec, eval_spec = minari_env_specs(logged)
    except SchemaMismatchError as e:
        return MinariEnvs(missing=e.message)
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            env = gym.make(spec)
        a = logged.arrays()
        space = env.observation_space
        if space.shape != a["obs"].shape[1:]:
            raise SchemaMismatchError(f"the env observes {space.shape}, the data holds {a['obs'].shape[1:]}")
        for k in ("obs", "next_obs"):
            if not (np.all(a[k] >= space.low) and np.all(a[k] <= space.high)):
                raise SchemaMismatchError(f"logged {k} fall outside the env's observation space")
    except DtradarError as e:
        return MinariEnvs(
            missing=f"twin {spec.kwargs['dataset']}@{spec.kwargs['version']}: {e.message}",
            retry=not isinstance(e, SchemaMismatchError),
        )
    return MinariEnvs(env, spec, eval_spec)


def env_text(spec) -> str:
    """A spec in one line, for the card and messages."""
    k = spec.kwargs
    return (
        f"{k['dataset']}@{k['version']} (obs {k['obs']}, reward {k['reward']}, max_steps {k['max_steps']}, noise "
        f"{k['noise']})"
    )


__all__ = ["MinariEnvs", "env_text", "minari_env_specs", "minari_envs"]
