"""A Minari dataset read back into dtradar's columns: :func:`from_minari` (ours or anyone's, by id or object) and
:func:`table_from_columns`, a checked transition table from them (what Minari does not hold, the robot, cell and
target of each step, is -1)."""

from __future__ import annotations

import contextlib
import io
from typing import Any

import numpy as np

from dtradar_data.core.errors import MissingDependencyError, SchemaMismatchError
from dtradar_data.store.logged import minari_root, transitions_table


def import_minari():
    """``minari``, imported quietly; a missing install is a typed error with the command that installs it."""
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            import minari
    except ImportError as e:
        raise MissingDependencyError(
            "Minari is not installed", hint="pip install 'dtradar[offline]' (or: pip install minari)"
        ) from e
    return minari


def from_minari(dataset: Any) -> dict[str, np.ndarray]:
    """Our columns (``episode, step, obs, action, reward, next_obs, terminated, truncated``) from a Minari dataset
    (a ``MinariDataset`` or its id)."""
    minari = import_minari()
    if isinstance(dataset, str):
        ours = minari_root() / dataset / "data"  # a copy of ours, MINARI_DATASETS_PATH set or not
        if ours.is_dir():
            from minari.dataset.minari_dataset import MinariDataset

            ds = MinariDataset(ours)
        else:
            ds = minari.load_dataset(dataset)
    else:
        ds = dataset
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


__all__ = ["from_minari", "import_minari", "table_from_columns"]
