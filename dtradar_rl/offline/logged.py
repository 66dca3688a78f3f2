"""Logged offline-RL datasets: log a behaviour policy on a twin into the store, and open the result as Minari or d3rlpy.

    from dtradar_rl.offline.logged import LogConfig, log_dataset, to_mdp_dataset, export_minari
    logged = log_dataset(LogConfig(scene="cubicle", behaviour="noisy-shortest"))   # cubicle/blueprint/noisy-shortest
    logged = dtradar_data.load("cubicle/blueprint/noisy-shortest")                 # the same, from the store
    mdp = to_mdp_dataset(logged)            # d3rlpy MDPDataset, every logged transition kept and aligned
    minari_id = export_minari(logged)       # minari.load_dataset("dtradar/cubicle-blueprint-noisy-shortest-v0")

Storage, names, versions and cards are :mod:`dtradar_data.store.transitions` (no torch there); the behaviour
policies and the rollout are :mod:`dtradar_rl.agents.behaviours`. This module joins them: :func:`log_dataset` computes the
version from the logging inputs *first*, so logging the same name with the same settings again only loads the stored
version.

Formats
-------
- **Parquet** (the store): ``transitions.parquet``, one row per step (:data:`TRANSITION_SCHEMA`), readable by polars,
  duckdb, pandas and the Hugging Face viewer.
- **Minari** (:func:`export_minari`, :func:`from_minari`): one Minari episode per logged episode, ``observations``
  holding ``L + 1`` rows (``obs`` of every step, then the last ``next_obs``), ``actions``/``rewards``/
  ``terminations``/``truncations`` ``L`` rows; written into Minari's own data path (``MINARI_DATASETS_PATH``, default
  ``~/.minari/datasets``) under ``dtradar/<scene>-<variant>-<behaviour>-v<N>`` (``N`` from the store's tag ``vN``).
- **d3rlpy** (:func:`to_mdp_dataset`): built from our table, not with ``d3rlpy.datasets.get_minari`` (which
  misaligns observations after the first episode in 2.8.1, DESIGN.md §4). d3rlpy drops the last step of an episode
  that ends in a timeout (it has no next observation there), so each truncated episode gets one extra row, its final
  ``next_obs`` with a dummy action, flagged as the timeout: every logged transition is then a d3rlpy transition with
  the right next observation. ``timeouts = truncated and not terminated`` (2.8.1 asserts on a step with both).
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import MissingDependencyError, SchemaMismatchError
from dtradar_data.store.transitions import (
    LoggedDataset,
    LoggedId,
    arrays,
    load_logged,
    local_versions,
    logged_version,
    logging_inputs,
    minari_id,
    parse_logged_id,
    table_digest,
    transitions_table,
    write_logged,
)

from dtradar_rl.agents.behaviours import BEHAVIOURS, BehaviourSpec, roll
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.runtime import auto_threads


@dataclass(frozen=True)
class LogConfig(TwinConfig):
    """Log a behaviour policy on a twin into the store as a versioned, carded dataset
    ``<scene>/<variant>/<name>``."""

    behaviour: str = "noisy-shortest"
    """behaviour policy: random, noisy-shortest, epsilon-greedy (a DQN checkpoint) or mixture (see --components)"""
    name: str = ""
    """third part of the dataset name (default: the behaviour)"""
    steps: int = 100_000
    """environment steps to log (all robots together; rounded up to whole steps of num-envs robots)"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the breadth-first shortest-path move at each step"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move instead of the checkpoint's greedy one"""
    checkpoint: str = ""
    """epsilon-greedy (and mixtures using it): the DQN model.pt written by `make train`"""
    components: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy")
    """mixture: the behaviours robots are split between (robot i uses component i mod k)"""
    minari: bool = True
    """also write the Minari copy (needs the [offline] extra: pip install minari)"""

    @property
    def logged_name(self) -> str:
        return f"{self.scene}/{self.variant}/{self.name or self.behaviour}"

    def spec(self) -> BehaviourSpec:
        return BehaviourSpec(self.behaviour, self.shortest_prob, self.epsilon, self.checkpoint,
                             tuple(self.components))

    def validate(self) -> LogConfig:
        super().validate()
        if self.behaviour not in BEHAVIOURS:
            from dtradar_data.core.errors import unknown_name

            raise unknown_name("behaviour policy", self.behaviour, BEHAVIOURS)
        self.check_at_least(1, "steps")
        parse_logged_id(self.logged_name)  # the name must fit the grammar
        self.spec().validate()
        return self


def parent_version(ds: Dataset) -> str:
    """The parent's stored content version, or a hash of its table (synthetic twins have no stored version)."""
    return ds.version or table_digest(ds.table)


def settings_of(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    from dtradar_rl.task.mdp import GridMDP

    max_steps = cfg.max_steps or GridMDP.from_dataset(ds).max_steps
    return {"num_envs": cfg.num_envs, "obs": cfg.obs, "reward": cfg.reward, "max_steps": int(max_steps),
            "device_kind": "cuda" if cfg.device.startswith("cuda") else "cpu"}


def log_inputs(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    return logging_inputs(parent=ds.name, parent_version=parent_version(ds), behaviour=cfg.spec().to_dict(),
                          steps=cfg.steps, seed=cfg.seed, settings=settings_of(cfg, ds))


def log_dataset(cfg: LogConfig, dataset: Dataset | None = None) -> LoggedDataset:
    """Log ``cfg.behaviour`` on ``cfg.dataset_name`` into the store (or reuse the stored version of the same inputs),
    write the Minari copy when ``cfg.minari``, and return the loaded dataset."""
    cfg = cfg.validate()
    import torch

    torch.set_num_threads(cfg.threads or auto_threads())
    say = print if cfg.verbose else (lambda *a, **k: None)
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    inputs = log_inputs(cfg, ds)
    version = logged_version(inputs)
    lid = parse_logged_id(cfg.logged_name)
    if version in local_versions(lid):
        logged = load_logged(lid, version)
        say(f"{lid.name}@{logged.tag} ({version}) is already logged with these settings: reused")
    else:
        normalizer = Normalizer.fit(ds)
        spec = cfg.spec()
        settings = inputs["settings"]
        r = roll(ds, spec, steps=cfg.steps, num_envs=cfg.num_envs, obs=cfg.obs, normalizer=normalizer,
                 reward=cfg.reward, max_steps=settings["max_steps"], seed=cfg.seed, device=cfg.device)
        c = r.columns
        table = transitions_table(episode=c["episode"], step=c["step"], obs=c["obs"], action=c["action"],
                                  reward=c["reward"], next_obs=c["next_obs"], terminated=c["terminated"],
                                  truncated=c["truncated"], robot=c["robot"], cell=c["cell"], target=c["target"],
                                  component=c["component"])
        names = list(build_observations(ds, cfg.obs, normalizer).names)
        meta = {"behaviour_text": spec.describe(), "normalizer": normalizer.to_dict(),
                "observations": {"preset": cfg.obs, "names": names}, "stats": {"rollout": r.stats}}
        version, _ = write_logged(lid, inputs, table, meta)
        logged = load_logged(lid, version)
        s = logged.meta["stats"]
        say(f"logged {lid.name}@{logged.tag} ({version}): {s['steps']} steps, {s['episodes']} episodes, behaviour "
            f"success {s['success_rate']:.3f}, mean return {s['mean_return']:.2f} in {r.stats['wall_s']:.1f} s")
    if cfg.minari:
        mid = export_minari(logged)
        say(f"Minari copy: minari.load_dataset({mid!r})")
    return logged


def as_logged(data: LoggedDataset | str | LoggedId) -> LoggedDataset:
    return data if isinstance(data, LoggedDataset) else load_logged(data)


# -- d3rlpy --------------------------------------------------------------------------------------------------------
def import_d3rlpy():
    """Import d3rlpy without the banner its ``import gym`` prints to stderr."""
    with contextlib.redirect_stderr(io.StringIO()):
        import d3rlpy
    return d3rlpy


@contextlib.contextmanager
def quiet_d3rlpy():
    """Silence d3rlpy's structlog info lines, restoring the config after."""
    import logging

    import structlog

    old = structlog.get_config()
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING))
    try:
        yield
    finally:
        structlog.configure(**old)


def d3rlpy_arrays(data: LoggedDataset | dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``observations, actions, rewards, terminals, timeouts`` for d3rlpy's ``MDPDataset``: our rows plus, after each
    truncated episode, one row holding its final ``next_obs`` (dummy action 0, reward 0) flagged as the timeout."""
    a = data.arrays() if isinstance(data, LoggedDataset) else data
    trunc = a["truncated"] & ~a["terminated"]
    at = np.flatnonzero(trunc) + 1  # insert after each truncated step
    obs = np.insert(a["obs"], at, a["next_obs"][trunc], axis=0)
    actions = np.insert(a["action"].astype(np.int64), at, 0)
    rewards = np.insert(a["reward"].astype(np.float32), at, 0.0)
    terminals = np.insert(a["terminated"].astype(np.float32), at, 0.0)
    timeouts = np.insert(np.zeros(len(trunc), np.float32), at, 1.0)
    return {"observations": obs.astype(np.float32), "actions": actions, "rewards": rewards, "terminals": terminals,
            "timeouts": timeouts}


def to_mdp_dataset(data: LoggedDataset | str | LoggedId):
    """The d3rlpy ``MDPDataset`` of a logged dataset (see the module docstring; discrete, 4 actions)."""
    d3rlpy = import_d3rlpy()
    arr = d3rlpy_arrays(as_logged(data))
    with quiet_d3rlpy():
        return d3rlpy.dataset.MDPDataset(
            observations=arr["observations"], actions=arr["actions"], rewards=arr["rewards"],
            terminals=arr["terminals"], timeouts=arr["timeouts"],
            action_space=d3rlpy.constants.ActionSpace.DISCRETE, action_size=4)


def check_compatible(logged: LoggedDataset, cfg: TwinConfig, ds: Dataset) -> None:
    """:class:`SchemaMismatchError` when ``logged`` was not logged on ``ds`` with ``cfg``'s observation preset (the
    trainer would otherwise learn from features another normaliser or preset produced)."""
    meta = logged.meta
    problems = []
    if meta.get("parent") != ds.name:
        problems.append(f"it was logged on {meta.get('parent')!r}, the trainer uses {ds.name!r}")
    elif meta.get("parent_version") != parent_version(ds):
        problems.append(f"it was logged on version {meta.get('parent_version')} of {ds.name}, the trainer loaded "
                        f"{parent_version(ds)}")
    preset = (meta.get("observations") or {}).get("preset")
    if preset != cfg.obs:
        problems.append(f"its observation preset is {preset!r}, the trainer's {cfg.obs!r}")
    stored = meta.get("normalizer")
    if stored and not problems:
        fitted = Normalizer.fit(ds)
        if not np.allclose(stored["mean"], fitted.mean, rtol=1e-5) or not np.allclose(stored["std"], fitted.std,
                                                                                         rtol=1e-5):
            problems.append("its feature normaliser differs from the one fitted on the twin")
    if problems:
        raise SchemaMismatchError(f"logged dataset {logged.name}@{logged.version} does not fit: " + "; ".join(problems),
                                  hint=f"train with --scene/--variant/--obs of the log (parent {meta.get('parent')}, "
                                       f"preset {preset}), or log again on this twin")


# -- Minari --------------------------------------------------------------------------------------------------------
def _minari():
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            import minari
    except ImportError as e:
        raise MissingDependencyError("Minari is not installed",
                                     hint="pip install 'dtradar[offline]' (or: pip install minari)") from e
    return minari


def minari_episodes(a: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """Our rows as Minari episodes: ``observations`` ``L + 1`` rows, the rest ``L``."""
    ends = np.flatnonzero(a["terminated"] | a["truncated"]) + 1
    starts = np.r_[0, ends[:-1]]
    out = []
    for s, e in zip(starts, ends):
        out.append({"observations": np.concatenate([a["obs"][s:e], a["next_obs"][e - 1:e]]),
                    "actions": a["action"][s:e].astype(np.int64), "rewards": a["reward"][s:e].astype(np.float64),
                    "terminations": a["terminated"][s:e].astype(bool), "truncations": a["truncated"][s:e].astype(bool)})
    return out


def export_minari(data: LoggedDataset | str | LoggedId, *, dataset_id: str | None = None, overwrite: bool = False) -> str:
    """Write the Minari copy of a logged version (in Minari's data path) and return its id; an existing copy of the
    same version is kept, one of another version is replaced only with ``overwrite``."""
    logged = as_logged(data)
    minari = _minari()
    import gymnasium as gym
    from minari.data_collector import EpisodeBuffer

    mid = dataset_id or logged.minari_id
    marker = f"dtradar {logged.name} version {logged.version}"
    if mid in minari.list_local_datasets():
        desc = str(minari.load_dataset(mid).storage.metadata.get("description") or "")
        if marker in desc:
            return mid
        if not overwrite:
            raise ConfigError(f"the Minari dataset {mid!r} exists but holds another dataset ({desc[:80]!r})",
                              hint=f"delete it (minari.delete_dataset({mid!r})) or pass overwrite=True")
        minari.delete_dataset(mid)
    a = logged.arrays()
    buffers = [EpisodeBuffer(id=i, observations=ep["observations"], actions=ep["actions"], rewards=list(ep["rewards"]),
                             terminations=list(ep["terminations"]), truncations=list(ep["truncations"]))
               for i, ep in enumerate(minari_episodes(a))]
    d = a["obs"].shape[1]
    s = logged.meta.get("stats") or {}
    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # no author e-mail, no gymnasium env spec: by design
        minari.create_dataset_from_buffers(
            dataset_id=mid, buffer=buffers, observation_space=gym.spaces.Box(-np.inf, np.inf, (d,), np.float32),
            action_space=gym.spaces.Discrete(4), algorithm_name=str((logged.meta.get("behaviour") or {}).get("kind")),
            author="dtradar", code_permalink="https://github.com/dtradar/dtradar",
            description=f"{marker}; parent {logged.meta.get('parent')}@{logged.meta.get('parent_version')}; "
                        f"behaviour success {s.get('success_rate', 0):.3f}; see the dtradar card (README.md) at "
                        f"{logged.path}")
    return mid


def from_minari(dataset: Any) -> dict[str, np.ndarray]:
    """Our columns (``episode, step, obs, action, reward, next_obs, terminated, truncated``) from a Minari dataset
    (a ``MinariDataset`` or its id)."""
    minari = _minari()
    ds = minari.load_dataset(dataset) if isinstance(dataset, str) else dataset
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("episode", "step", "obs", "action", "reward", "next_obs",
                                                         "terminated", "truncated")}
    for i, ep in enumerate(ds.iterate_episodes()):
        obs = np.asarray(ep.observations, np.float32)
        n = len(ep.actions)
        if len(obs) != n + 1:
            raise SchemaMismatchError(f"Minari episode {ep.id} has {len(obs)} observations for {n} actions "
                                      "(expected actions + 1)", hint="export it again with export_minari")
        cols["episode"].append(np.full(n, i, np.int64))
        cols["step"].append(np.arange(n, dtype=np.int32))
        cols["obs"].append(obs[:-1])
        cols["next_obs"].append(obs[1:])
        cols["action"].append(np.asarray(ep.actions, np.int64))
        cols["reward"].append(np.asarray(ep.rewards, np.float32))
        cols["terminated"].append(np.asarray(ep.terminations, bool))
        cols["truncated"].append(np.asarray(ep.truncations, bool))
    return {k: np.concatenate(v) for k, v in cols.items()}


def table_from_columns(c: dict[str, np.ndarray]):
    """A checked transition table from :func:`from_minari`'s columns (robot, cell, target, component unknown: -1/0)."""
    n = len(c["action"])
    minus = np.full(n, -1, np.int32)
    return transitions_table(episode=c["episode"], step=c["step"], obs=c["obs"], action=c["action"],
                             reward=c["reward"], next_obs=c["next_obs"], terminated=c["terminated"],
                             truncated=c["truncated"], robot=minus, cell=minus, target=minus)


__all__ = ["LogConfig", "arrays", "as_logged", "check_compatible", "d3rlpy_arrays", "export_minari", "from_minari",
           "log_dataset", "minari_episodes", "minari_id", "parent_version", "table_from_columns", "to_mdp_dataset"]
