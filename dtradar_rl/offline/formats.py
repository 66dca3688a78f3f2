"""The formats of a logged offline-RL dataset: the store's Parquet table opened as Minari or as d3rlpy.

Formats
-------
- **Parquet** (the store): ``transitions.parquet``, one row per step (:data:`TRANSITION_SCHEMA`), readable by polars,
  duckdb, pandas and the Hugging Face viewer.
- **Minari** (:mod:`dtradar_rl.offline.minari_copy`: ``export_minari``, ``from_minari``): one Minari episode per
  logged episode, ``observations`` holding ``L + 1`` rows (``obs`` of every step, then the last ``next_obs``),
  ``actions``/``rewards``/``terminations``/``truncations`` ``L`` rows; written under
  ``dtradar/<scene>-<variant>-<behaviour>-v<N>`` (``N`` from the store's tag ``vN``) into ``MINARI_DATASETS_PATH``
  when it is set, else into ``<data root>/minari``: one Minari folder per data root, since each root numbers its tags
  from ``v0`` (:func:`~dtradar_data.store.logged.minari_root`). The copy is staged and renamed into place (whole or
  absent), recorded (``dtradar.json``), checked before it is reused and rewritten when incomplete
  (``export_minari``); ``load_minari`` opens it. It records the env spec of the twin it was logged on
  (:mod:`dtradar_rl.offline.minari_envs`), so ``recover_environment()`` gives the logging env and
  ``recover_environment(eval_env=True)`` the evaluation env (the dynamic twin of a blueprint log), and its
  observation space is that env's.
- **d3rlpy** (:func:`to_mdp_dataset`): built from our table, not with ``d3rlpy.datasets.get_minari`` (which
  misaligns observations after the first episode in 2.8.1; docs: Logged datasets). d3rlpy drops the last step of an
  episode that ends in a timeout (it has no next observation there), so each truncated episode gets one extra row,
  its final ``next_obs`` with a dummy action, flagged as the timeout: every logged transition is then a d3rlpy
  transition with the right next observation. ``timeouts = truncated and not terminated`` (2.8.1 asserts on a step
  with both).
"""

from __future__ import annotations

import contextlib
import io

import numpy as np

from dtradar_data.store.logged import (
    LoggedDataset,
    LoggedId,
    load_logged,
)


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


def to_mdp_dataset(data: LoggedDataset | str | LoggedId | dict[str, np.ndarray]):
    """The d3rlpy ``MDPDataset`` of a logged dataset, or of its arrays (see the module docstring; discrete, 4
    actions)."""
    d3rlpy = import_d3rlpy()
    arr = d3rlpy_arrays(data if isinstance(data, dict) else as_logged(data))
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


__all__ = ["as_logged", "d3rlpy_arrays", "import_d3rlpy", "quiet_d3rlpy", "to_mdp_dataset"]
