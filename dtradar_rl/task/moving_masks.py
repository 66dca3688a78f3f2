"""A moving twin's masks, read from its per-cell table: what is blocked and what a mover covers at each snapshot
(:func:`moving_masks`, checked against the format), and the twin as one static twin (:func:`background`).

A moving twin (:mod:`dtradar_data.core.dataset`) holds ``T`` snapshots of one grid, rows sorted by ``(t, iy, ix)``;
``blocked`` is a static obstacle or a mover, ``mover`` the movers' part of it. The MDP in time built on these masks
is :class:`~dtradar_rl.task.grid_mdp.MovingGridMDP`.
"""

from __future__ import annotations

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import SchemaMismatchError


def moving_masks(ds: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """``(blocked, mover)``, each ``bool[T, H*W]``, of a moving twin, checked against the format: rows sorted by
    ``(t, iy, ix)``, ``mover`` a subset of ``blocked``, and the static obstacles (``blocked & ~mover``) the same in
    every snapshot; anything else is a :class:`SchemaMismatchError`."""
    t_count = ds.snapshots
    h, w = ds.shape
    n = h * w
    table = ds.table
    if "mover" not in table.column_names:
        raise SchemaMismatchError(
            f"{ds.name}: a moving twin needs a bool 'mover' column (the blocked cells a mover covers at snapshot t)",
            hint="rebuild it with make dataset SCENE=<scene> VARIANT=moving (its format: docs/explanation/mdp.md, "
            "Navigation among movers)",
        )
    col = lambda name: table.column(name).to_numpy(zero_copy_only=False)  # noqa: E731
    t, ix, iy = col("t"), col("ix"), col("iy")
    iy_ref, ix_ref = np.divmod(np.arange(n), w)
    if not (
        (t.reshape(t_count, n) == np.arange(t_count)[:, None]).all()
        and (ix.reshape(t_count, n) == ix_ref).all()
        and (iy.reshape(t_count, n) == iy_ref).all()
    ):
        raise SchemaMismatchError(
            f"{ds.name}: rows are not every cell of every snapshot in (t, iy, ix) order",
            hint="sort the table by (t, iy, ix) (Dataset.from_table does) with all H x W cells per snapshot",
        )
    blocked = col("blocked").astype(bool).reshape(t_count, n)
    mover = col("mover").astype(bool).reshape(t_count, n)
    if (mover & ~blocked).any():
        k, c = (int(v) for v in np.argwhere(mover & ~blocked)[0])
        raise SchemaMismatchError(
            f"{ds.name}: cell {tuple(int(v) for v in np.divmod(c, w)[::-1])} has a mover but is not blocked at "
            f"snapshot {k}",
            hint="blocked = static obstacle or mover",
        )
    static = blocked & ~mover
    if (static != static[:1]).any():
        k = int(np.flatnonzero((static != static[:1]).any(1))[0])
        raise SchemaMismatchError(
            f"{ds.name}: the static obstacles (blocked and not mover) of snapshot {k} differ from snapshot 0",
            hint="mark every cell that changes over time as a mover",
        )
    return blocked, mover


def background(ds: Dataset) -> Dataset:
    """A moving twin as one static twin: every cell as it is in the first snapshot in which it is free (blocked only
    where it is blocked in every snapshot), no ``t``/``mover`` columns, ``meta`` without ``"moving"``. A map and a
    fingerprint table for a planner; a static twin is its own background."""
    if not ds.is_moving:
        return ds
    blocked, _ = moving_masks(ds)
    n = blocked.shape[1]
    first_free = (~blocked).argmax(0)  # 0 where blocked in every snapshot
    rows = first_free * n + np.arange(n)
    table = ds.table.take(rows).drop_columns(["t", "mover"])
    meta = {key: v for key, v in ds.meta.items() if key != "moving"}
    return Dataset(ds.name, table, meta, ds.version, ds.path)
