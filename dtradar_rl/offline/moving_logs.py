"""Logs on a moving twin (``<scene>/moving/<behaviour>``): what they keep of time, and what they refuse.

A moving twin's log is rolled out by the same engine as a static twin's (:func:`~dtradar_rl.offline.collection.roll`)
in the batched env among the movers (:class:`~dtradar_rl.task.grid_mdp.MovingGridMDP`): every episode starts at a
snapshot drawn with its pair, each robot step advances one snapshot, a move into a mover is a collision (the robot
stays) and a mover may walk onto the robot. The robots have the four moves: the wait action of ``make train
VARIANT=moving`` is an option of online training, and every offline learner acts with the four moves of a log.

The transition table has no column for time (its schema is every log's), so the snapshot of every step is kept in
``meta["moving"]``: each episode's start snapshot, from which step ``k`` of an episode is in snapshot
``(start + k) mod snapshots`` (:func:`step_snapshots`). The SPL of the logged episodes is measured as evaluation
measures it on a moving twin (:func:`~dtradar_rl.evaluation.normalized.logged_episodes_spl` given the snapshots).

Refused before anything is rolled out (:func:`check_moving_log`): ``--minari-memory``, whose memory window is rebuilt
from the static map's moves, which on a moving twin depend on the snapshot; and a checkpoint that cannot act in a log
(:func:`~dtradar_rl.offline.checkpoint_twin.checkpoint_policy`: one with the wait action or the clock). A trainer
learns from such a log memoryless and on its logged targets (the memory window and relabelling are refused there
too: :mod:`dtradar_rl.offline.senses`, :mod:`dtradar_rl.offline.relabel`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.task.config import ConfigError

__all__ = ["MovingLogError", "check_moving_log", "moving_meta", "step_snapshots"]

#: What works on a moving twin, named by every refusal.
WORKS = (
    "every dataset family (random, expert, medium, medium-replay, mixed, navigate, stitch, explore) and "
    "noisy-shortest, privileged or honest --sensing, with the plain Minari copy"
)


class MovingLogError(ConfigError):
    """A log setting that cannot apply on a moving twin, refused before anything is rolled out; the message says
    why, the hint what to log instead."""


def check_moving_log(cfg: Any, ds: Dataset) -> None:
    """:class:`MovingLogError` for a setting of ``cfg`` (a :class:`~dtradar_rl.offline.logged.LogConfig`) that cannot
    apply on the moving twin ``ds``; nothing on a static twin."""
    if not ds.is_moving:
        return
    if cfg.minari_memory:
        raise MovingLogError(
            f"--minari-memory on the moving twin {ds.name}: the memory window is rebuilt from the twin's moves, "
            "which among movers depend on the snapshot",
            hint=f"drop --minari-memory (on a moving twin: {WORKS})",
        )


def moving_meta(ds: Dataset, columns: dict[str, np.ndarray]) -> dict[str, Any]:
    """``meta["moving"]`` of a log on the moving twin ``ds`` from the rollout's ``columns`` (with ``snapshot``): the
    schedule, the actions and each episode's start snapshot (module docstring)."""
    first = np.r_[True, columns["episode"][1:] != columns["episode"][:-1]]
    moving = ds.meta.get("moving") or {}
    return {
        "snapshots": int(ds.snapshots),
        "dt_s": moving.get("dt_s"),
        "movers": list(moving.get("movers") or []),
        "actions": "the four moves (no wait action): a robot waits only by bumping into a wall or a mover",
        "start_snapshots": [int(t) for t in columns["snapshot"][first]],
        "step_snapshot": "(start_snapshots[episode] + step) mod snapshots",
    }


def step_snapshots(logged: LoggedDataset) -> np.ndarray | None:
    """``int64[steps]``: the snapshot each logged step starts in, for a log on a moving twin (None for a static
    twin's); :class:`SchemaMismatchError` when its meta does not hold one start per episode."""
    moving = logged.meta.get("moving")
    if not moving:
        return None
    episode = logged.table.column("episode").to_numpy()
    step = logged.table.column("step").to_numpy()
    starts = np.asarray(moving.get("start_snapshots") or [], np.int64)
    if episode.size and starts.size != int(episode.max()) + 1:
        raise SchemaMismatchError(
            f"{logged.name}@{logged.version}: its meta holds {starts.size} start snapshots for "
            f"{int(episode.max()) + 1} episodes",
            hint="log it again (python -m dtradar_rl log ...)",
        )
    return (starts[episode] + step) % int(moving["snapshots"])
