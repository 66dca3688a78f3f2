"""Logged offline-RL datasets: log a behaviour policy on a twin into the store, and open the result as Minari or d3rlpy.

    from dtradar_rl.offline.logged import LogConfig, log_dataset
    from dtradar_rl.offline.formats import to_mdp_dataset, export_minari
    logged = log_dataset(LogConfig(scene="cubicle", behaviour="noisy-shortest"))   # cubicle/blueprint/noisy-shortest
    logged = dtradar_data.load("cubicle/blueprint/noisy-shortest")                 # the same, from the store
    mdp = to_mdp_dataset(logged)            # d3rlpy MDPDataset, every logged transition kept and aligned
    minari_id = export_minari(logged)       # "dtradar/cubicle-blueprint-noisy-shortest-v0" in <data root>/minari

Storage, names, versions and cards are :mod:`dtradar_data.store.logged` (no torch there); the behaviour
policies are :mod:`dtradar_rl.offline.behaviours` and the one rollout engine :mod:`dtradar_rl.offline.collection`. This
module joins them: :func:`log_dataset` computes the version from the logging inputs *first*, so logging the same name
with the same settings again only loads the stored version (and replaces it when it is damaged). Two processes logging
the same version take turns (the second says what it waits for, then reuses the first's); staging folders that a
killed run left in ``<root>/work`` are removed first.

Its formats (Parquet in the store, Minari, d3rlpy) are :mod:`dtradar_rl.offline.formats`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError
from dtradar_data.store.logged import (
    MINARI_ENV,
    LoggedDataset,
    clean_logged_stages,
    load_logged,
    local_versions,
    logged_version,
    logging_inputs,
    logging_lock,
    minari_root,
    parse_logged_id,
    table_digest,
    transitions_table,
    write_logged,
)
from dtradar_rl.offline.behaviours import BehaviourConfig
from dtradar_rl.offline.collection import roll
from dtradar_rl.offline.formats import export_minari
from dtradar_rl.task.config import TwinConfig
from dtradar_rl.task.mdp import GridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.twins import load_dataset


@dataclass(frozen=True)
class LogConfig(BehaviourConfig):
    """Log a behaviour policy on a twin into the store as a versioned, carded dataset
    ``<scene>/<variant>/<name>``."""

    name: str = ""
    """third part of the dataset name (default: the behaviour)"""
    steps: int = 100_000
    """environment steps to log (all robots together; rounded up to whole steps of num-envs robots)"""
    minari: bool = True
    """also write the Minari copy (needs the [offline] extra: pip install minari)"""

    @property
    def logged_name(self) -> str:
        return f"{self.scene}/{self.variant}/{self.name or self.behaviour}"

    def validate(self) -> LogConfig:
        super().validate()
        self.check_at_least(1, "steps")
        parse_logged_id(self.logged_name)  # the name must fit the grammar
        return self


def parent_version(ds: Dataset) -> str:
    """The parent's stored content version, or a hash of its table (synthetic twins have no stored version)."""
    return ds.version or table_digest(ds.table)


def settings_of(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    max_steps = cfg.max_steps or GridMDP.from_dataset(ds).max_steps
    return {
        "num_envs": cfg.num_envs,
        "obs": cfg.obs,
        "reward": cfg.reward,
        "max_steps": int(max_steps),
        "device_kind": "cuda" if cfg.device.startswith("cuda") else "cpu",
    }


def log_inputs(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    return logging_inputs(
        parent=ds.name,
        parent_version=parent_version(ds),
        behaviour=cfg.spec().to_dict(),
        steps=cfg.steps,
        seed=cfg.seed,
        settings=settings_of(cfg, ds),
    )


def _stored(lid, version: str, say) -> LoggedDataset | None:
    """The stored ``lid@version`` if it loads and verifies; None when absent or damaged (then logged again)."""
    if version not in local_versions(lid, damaged=True):
        return None
    try:
        return load_logged(lid, version)
    except (CorruptDatasetError, SchemaMismatchError) as exc:
        say(f"{lid.name}@{version} is stored but damaged ({exc.message}): logging it again")
        return None


def log_dataset(cfg: LogConfig, dataset: Dataset | None = None) -> LoggedDataset:
    """Log ``cfg.behaviour`` on ``cfg.dataset_name`` into the store (or reuse the stored version of the same inputs;
    a damaged one is logged again), write the Minari copy when ``cfg.minari``, and return the loaded dataset."""
    cfg = cfg.validate()
    import torch

    torch.set_num_threads(cfg.threads or auto_threads())
    say = print if cfg.verbose else (lambda *a, **k: None)
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    inputs = log_inputs(cfg, ds)
    version = logged_version(inputs)
    lid = parse_logged_id(cfg.logged_name)
    clean_logged_stages()
    with logging_lock(lid, version):
        logged = _stored(lid, version, say)
        if logged is not None:
            say(f"{lid.name}@{logged.tag} ({version}) is already logged with these settings: reused")
        else:
            logged = _log(cfg, ds, lid, inputs, say)
    if cfg.minari:
        mid = export_minari(logged)
        say(f"Minari copy: {logged.minari_path} (load: {MINARI_ENV}={minari_root()} minari.load_dataset({mid!r}))")
    return logged


def _log(cfg: LogConfig, ds: Dataset, lid, inputs: dict[str, Any], say) -> LoggedDataset:
    """Roll the behaviour out, store the table as a version and load it back."""
    normalizer = Normalizer.fit(ds)
    spec = cfg.spec()
    settings = inputs["settings"]
    r = roll(
        ds,
        spec,
        steps=cfg.steps,
        num_envs=cfg.num_envs,
        obs=cfg.obs,
        normalizer=normalizer,
        reward=cfg.reward,
        max_steps=settings["max_steps"],
        seed=cfg.seed,
        device=cfg.device,
    )
    c = r.columns
    table = transitions_table(
        episode=c["episode"],
        step=c["step"],
        obs=c["obs"],
        action=c["action"],
        reward=c["reward"],
        next_obs=c["next_obs"],
        terminated=c["terminated"],
        truncated=c["truncated"],
        robot=c["robot"],
        cell=c["cell"],
        target=c["target"],
        component=c["component"],
    )
    names = list(build_observations(ds, cfg.obs, normalizer).names)
    meta = {
        "behaviour_text": spec.describe(),
        "normalizer": normalizer.to_dict(),
        "observations": {"preset": cfg.obs, "names": names},
        "stats": {"rollout": r.stats},
    }
    version, _ = write_logged(lid, inputs, table, meta)
    logged = load_logged(lid, version)
    s = logged.meta["stats"]
    say(
        f"logged {lid.name}@{logged.tag} ({version}): {s['steps']} steps, {s['episodes']} episodes, behaviour "
        f"success {s['success_rate']:.3f}, mean return {s['mean_return']:.2f} in {r.stats['wall_s']:.1f} s"
    )
    return logged


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
    preset = (meta.get("observations") or {}).get("preset")
    if preset != cfg.obs:
        problems.append(f"its observation preset is {preset!r}, the trainer's {cfg.obs!r}")
    stored = meta.get("normalizer")
    if stored and not problems:
        fitted = Normalizer.fit(ds)
        if not np.allclose(stored["mean"], fitted.mean, rtol=1e-5) or not np.allclose(
            stored["std"], fitted.std, rtol=1e-5
        ):
            problems.append("its feature normaliser differs from the one fitted on the twin")
    if problems:
        raise SchemaMismatchError(
            f"logged dataset {logged.name}@{logged.version} does not fit: " + "; ".join(problems),
            hint=f"train with --scene/--variant/--obs of the log (parent {meta.get('parent')}, "
            f"preset {preset}), or log again on this twin",
        )


__all__ = ["LogConfig", "check_compatible", "log_dataset", "log_inputs", "parent_version", "settings_of"]
