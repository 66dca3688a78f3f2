"""What ties a logged dataset to the twin and settings it was logged with: the parent's version, the logging settings
that enter a version, and the check a trainer runs before it learns from a log."""

from __future__ import annotations

from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.store.logged import LoggedDataset, table_digest
from dtradar_rl.offline.behaviours import BehaviourConfig
from dtradar_rl.task.config import TwinConfig
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer


def parent_version(ds: Dataset) -> str:
    """The parent's stored content version, or a hash of its table (synthetic twins have no stored version)."""
    return ds.version or table_digest(ds.table)


def settings_of(cfg: BehaviourConfig, ds: Dataset) -> dict[str, Any]:
    """The logging settings that enter a log's version and a medium agent's key: robots, observation preset, reward,
    step limit (the twin's default when unset) and device kind."""
    max_steps = cfg.max_steps or GridMDP.from_dataset(ds).max_steps
    out = {
        "num_envs": cfg.num_envs,
        "obs": cfg.obs,
        "reward": cfg.reward,
        "max_steps": int(max_steps),
        "device_kind": "cuda" if cfg.device.startswith("cuda") else "cpu",
    }
    if cfg.honest:  # only then: a privileged log's version stays what it was before sensings existed
        out.update(sensing=cfg.sensing, sensing_noise=cfg.sensing_noise)
    return out


def check_compatible(logged: LoggedDataset, cfg: TwinConfig, ds: Dataset) -> None:
    """:class:`SchemaMismatchError` when ``logged`` was not logged on ``ds`` with ``cfg``'s observation preset (the
    trainer would otherwise learn from features another normaliser or preset produced)."""
    meta = logged.meta
    problems = []
    if meta.get("parent") != ds.name:
        problems.append(f"it was logged on {meta.get('parent')!r}, the trainer uses {ds.name!r}")
    elif meta.get("parent_version") != parent_version(ds):
        problems.append(
            f"it was logged on version {meta.get('parent_version')} of {ds.name}, the trainer loaded "
            f"{parent_version(ds)}"
        )
    observations = meta.get("observations") or {}
    preset = observations.get("preset")
    logged_sensing = observations.get("sensing", "privileged")  # logs made before sensings existed: privileged
    sensing = getattr(cfg, "sensing", "privileged")
    if logged_sensing != sensing:
        problems.append(f"it records --sensing {logged_sensing}, the trainer's is {sensing}")
    elif logged_sensing == "privileged" and preset != cfg.obs:
        problems.append(f"its observation preset is {preset!r}, the trainer's {cfg.obs!r}")
    stored = meta.get("normalizer")
    if stored and not problems:
        fitted = Normalizer.fit(ds)
        if tuple(stored.get("columns", fitted.columns)) != fitted.columns:  # another count of transmitters
            problems.append(
                f"its feature normaliser holds {len(stored['columns'])} columns, the twin's {len(fitted.columns)}"
            )
        elif not np.allclose(stored["mean"], fitted.mean, rtol=1e-5) or not np.allclose(
            stored["std"], fitted.std, rtol=1e-5
        ):
            problems.append("its feature normaliser differs from the one fitted on the twin")
    if problems:
        raise SchemaMismatchError(
            f"logged dataset {logged.name}@{logged.version} does not fit: " + "; ".join(problems),
            hint=f"train with --scene/--variant/--obs/--sensing of the log (parent {meta.get('parent')}, "
            f"preset {preset}, sensing {logged_sensing}), or log again on this twin",
        )


__all__ = ["check_compatible", "parent_version", "settings_of"]
