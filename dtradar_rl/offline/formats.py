"""The formats of a logged offline-RL dataset: the store's Parquet table opened as Minari or as d3rlpy.

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
from typing import Any

import numpy as np

from dtradar_data.core.errors import MissingDependencyError, SchemaMismatchError
from dtradar_data.store.logged import LoggedDataset, LoggedId, load_logged, transitions_table
from dtradar_rl.task.config import ConfigError


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
    return {
        "observations": obs.astype(np.float32),
        "actions": actions,
        "rewards": rewards,
        "terminals": terminals,
        "timeouts": timeouts,
    }


def to_mdp_dataset(data: LoggedDataset | str | LoggedId):
    """The d3rlpy ``MDPDataset`` of a logged dataset (see the module docstring; discrete, 4 actions)."""
    d3rlpy = import_d3rlpy()
    arr = d3rlpy_arrays(as_logged(data))
    with quiet_d3rlpy():
        return d3rlpy.dataset.MDPDataset(
            observations=arr["observations"],
            actions=arr["actions"],
            rewards=arr["rewards"],
            terminals=arr["terminals"],
            timeouts=arr["timeouts"],
            action_space=d3rlpy.constants.ActionSpace.DISCRETE,
            action_size=4,
        )


# -- Minari --------------------------------------------------------------------------------------------------------
def _minari():
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            import minari
    except ImportError as e:
        raise MissingDependencyError(
            "Minari is not installed", hint="pip install 'dtradar[offline]' (or: pip install minari)"
        ) from e
    return minari


def minari_episodes(a: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """Our rows as Minari episodes: ``observations`` ``L + 1`` rows, the rest ``L``."""
    ends = np.flatnonzero(a["terminated"] | a["truncated"]) + 1
    starts = np.r_[0, ends[:-1]]
    out = []
    for s, e in zip(starts, ends):
        out.append(
            {
                "observations": np.concatenate([a["obs"][s:e], a["next_obs"][e - 1 : e]]),
                "actions": a["action"][s:e].astype(np.int64),
                "rewards": a["reward"][s:e].astype(np.float64),
                "terminations": a["terminated"][s:e].astype(bool),
                "truncations": a["truncated"][s:e].astype(bool),
            }
        )
    return out


def export_minari(
    data: LoggedDataset | str | LoggedId, *, dataset_id: str | None = None, overwrite: bool = False
) -> str:
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
            raise ConfigError(
                f"the Minari dataset {mid!r} exists but holds another dataset ({desc[:80]!r})",
                hint=f"delete it (minari.delete_dataset({mid!r})) or pass overwrite=True",
            )
        minari.delete_dataset(mid)
    a = logged.arrays()
    buffers = [
        EpisodeBuffer(
            id=i,
            observations=ep["observations"],
            actions=ep["actions"],
            rewards=list(ep["rewards"]),
            terminations=list(ep["terminations"]),
            truncations=list(ep["truncations"]),
        )
        for i, ep in enumerate(minari_episodes(a))
    ]
    d = a["obs"].shape[1]
    s = logged.meta.get("stats") or {}
    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # no author e-mail, no gymnasium env spec: by design
        minari.create_dataset_from_buffers(
            dataset_id=mid,
            buffer=buffers,
            observation_space=gym.spaces.Box(-np.inf, np.inf, (d,), np.float32),
            action_space=gym.spaces.Discrete(4),
            algorithm_name=str((logged.meta.get("behaviour") or {}).get("kind")),
            author="dtradar",
            code_permalink="https://github.com/dtradar/dtradar",
            description=f"{marker}; parent {logged.meta.get('parent')}@{logged.meta.get('parent_version')}; "
            f"behaviour success {s.get('success_rate', 0):.3f}; see the dtradar card (README.md) at "
            f"{logged.path}",
        )
    return mid


def from_minari(dataset: Any) -> dict[str, np.ndarray]:
    """Our columns (``episode, step, obs, action, reward, next_obs, terminated, truncated``) from a Minari dataset
    (a ``MinariDataset`` or its id)."""
    minari = _minari()
    ds = minari.load_dataset(dataset) if isinstance(dataset, str) else dataset
    cols: dict[str, list[np.ndarray]] = {
        k: [] for k in ("episode", "step", "obs", "action", "reward", "next_obs", "terminated", "truncated")
    }
    for i, ep in enumerate(ds.iterate_episodes()):
        obs = np.asarray(ep.observations, np.float32)
        n = len(ep.actions)
        if len(obs) != n + 1:
            raise SchemaMismatchError(
                f"Minari episode {ep.id} has {len(obs)} observations for {n} actions (expected actions + 1)",
                hint="export it again with export_minari",
            )
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
    return transitions_table(
        episode=c["episode"],
        step=c["step"],
        obs=c["obs"],
        action=c["action"],
        reward=c["reward"],
        next_obs=c["next_obs"],
        terminated=c["terminated"],
        truncated=c["truncated"],
        robot=minus,
        cell=minus,
        target=minus,
    )


__all__ = [
    "as_logged",
    "d3rlpy_arrays",
    "export_minari",
    "from_minari",
    "import_d3rlpy",
    "minari_episodes",
    "quiet_d3rlpy",
    "table_from_columns",
    "to_mdp_dataset",
]
