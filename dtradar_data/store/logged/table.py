"""The transition table of a logged dataset: its schema, its invariants, numpy views and episode statistics.

One row per environment step, episodes contiguous and in order (:data:`TRANSITION_SCHEMA`):
``episode, step, obs, action, reward, next_obs, terminated, truncated, robot, cell, target, component``.
``obs`` is the observation the action was chosen from, ``next_obs`` the one after the move; within an episode
``next_obs[t] == obs[t + 1]``. The last step of every episode has exactly one flag: ``terminated`` (the target was
reached: a true terminal, bootstrap with 0) or ``truncated`` (cut by the step limit or by the end of logging: not a
terminal, bootstrap from ``next_obs``); no other step has either. :func:`check_transitions` enforces all of it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError

__all__ = [
    "TRANSITIONS_FORMAT",
    "TRANSITIONS_FILE",
    "TRANSITION_SCHEMA",
    "COLUMN_DESCRIPTIONS",
    "transitions_table",
    "arrays",
    "check_transitions",
    "episode_stats",
]

TRANSITIONS_FORMAT = 1
TRANSITIONS_FILE = "transitions.parquet"

TRANSITION_SCHEMA = pa.schema(
    [
        pa.field("episode", pa.int64(), nullable=False, metadata={"description": "episode number, 0.. in file order"}),
        pa.field("step", pa.int32(), nullable=False, metadata={"description": "step within the episode, 0.."}),
        pa.field(
            "obs",
            pa.list_(pa.float32()),
            nullable=False,
            metadata={"description": "normalised observation the action was chosen from"},
        ),
        pa.field("action", pa.int8(), nullable=False, metadata={"description": "0 X-, 1 X+, 2 Y-, 3 Y+"}),
        pa.field("reward", pa.float32(), nullable=False, metadata={"description": "reward of the move"}),
        pa.field(
            "next_obs",
            pa.list_(pa.float32()),
            nullable=False,
            metadata={"description": "observation after the move (the next row's obs within an episode)"},
        ),
        pa.field(
            "terminated",
            pa.bool_(),
            nullable=False,
            metadata={"description": "the move reached the target: the episode ends in a true terminal"},
        ),
        pa.field(
            "truncated",
            pa.bool_(),
            nullable=False,
            metadata={"description": "the episode was cut here (step limit or end of logging), not a terminal"},
        ),
        pa.field("robot", pa.int32(), nullable=False, metadata={"description": "which parallel robot logged the step"}),
        pa.field("cell", pa.int32(), nullable=False, metadata={"description": "row-major cell index before the move"}),
        pa.field("target", pa.int32(), nullable=False, metadata={"description": "the episode's target cell index"}),
        pa.field(
            "component",
            pa.int8(),
            nullable=False,
            metadata={
                "description": "mixture component that acted (index into meta behaviour.components; 0 "
                "for a single policy)"
            },
        ),
    ]
)
COLUMN_DESCRIPTIONS = {f.name: f.metadata[b"description"].decode() for f in TRANSITION_SCHEMA}


def transitions_table(
    *, episode, step, obs, action, reward, next_obs, terminated, truncated, robot, cell, target, component=None
) -> pa.Table:
    """The transition table from numpy arrays (``obs``/``next_obs``: float32[T, D]), checked by
    :func:`check_transitions`."""
    obs = np.ascontiguousarray(obs, np.float32)
    next_obs = np.ascontiguousarray(next_obs, np.float32)
    n = len(obs)
    if obs.ndim != 2 or next_obs.shape != obs.shape:
        raise SchemaMismatchError(
            f"obs {obs.shape} and next_obs {next_obs.shape} must both be [T, D]",
            hint="pass one observation row per step",
        )

    def lists(x: np.ndarray) -> pa.Array:
        offsets = pa.array(np.arange(0, n * x.shape[1] + 1, x.shape[1], dtype=np.int32))
        return pa.ListArray.from_arrays(offsets, pa.array(x.reshape(-1)))

    comp = np.zeros(n, np.int8) if component is None else np.asarray(component, np.int8)
    cols = [
        np.asarray(episode, np.int64),
        np.asarray(step, np.int32),
        lists(obs),
        np.asarray(action, np.int8),
        np.asarray(reward, np.float32),
        lists(next_obs),
        np.asarray(terminated, bool),
        np.asarray(truncated, bool),
        np.asarray(robot, np.int32),
        np.asarray(cell, np.int32),
        np.asarray(target, np.int32),
        comp,
    ]
    table = pa.Table.from_arrays(
        [c if isinstance(c, pa.Array) else pa.array(c) for c in cols], schema=TRANSITION_SCHEMA
    )
    check_transitions(table)
    return table


def _matrix(column: pa.ChunkedArray | pa.Array, what: str) -> np.ndarray:
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if len(arr) == 0:
        return np.zeros((0, 0), np.float32)
    lengths = np.diff(arr.offsets.to_numpy())
    if lengths.min() != lengths.max():
        raise CorruptDatasetError(
            f"{what} rows have different lengths ({lengths.min()}..{lengths.max()})", hint="log the dataset again"
        )
    values = arr.flatten().to_numpy(zero_copy_only=False)
    return values.reshape(len(arr), int(lengths[0])).astype(np.float32, copy=False)


def arrays(table: pa.Table) -> dict[str, np.ndarray]:
    """Every column as numpy (``obs``/``next_obs`` as float32[T, D])."""
    out = {}
    for f in TRANSITION_SCHEMA:
        col = table.column(f.name)
        out[f.name] = _matrix(col, f.name) if f.name in ("obs", "next_obs") else col.to_numpy()
    return out


def check_transitions(table: pa.Table, where: str = "transition table") -> None:
    """:class:`SchemaMismatchError` for another schema, :class:`CorruptDatasetError` for rows that do not form
    contiguous episodes with exactly one end flag each and ``next_obs[t] == obs[t+1]`` inside an episode."""
    diff = [n for n in TRANSITION_SCHEMA.names if n not in table.column_names]
    wrong = [
        f"{f.name}: {table.schema.field(f.name).type} (expected {f.type})"
        for f in TRANSITION_SCHEMA
        if f.name in table.column_names and table.schema.field(f.name).type != f.type
    ]
    if diff or wrong:
        raise SchemaMismatchError(
            f"{where} does not match the transition schema v{TRANSITIONS_FORMAT}: "
            + "; ".join([f"missing column {n!r}" for n in diff] + wrong),
            hint="log the dataset again with this dtradar",
        )
    a = arrays(table)
    n = len(a["action"])
    if n == 0:
        raise CorruptDatasetError(f"{where} has no rows", hint="log at least one step")

    def bad(msg: str):
        raise CorruptDatasetError(f"{where}: {msg}", hint="log the dataset again; never edit a transition table")

    ep, step = a["episode"], a["step"]
    new = np.r_[True, ep[1:] != ep[:-1]]
    if ep[0] != 0 or np.any(np.diff(ep) < 0) or np.any(np.diff(ep) > 1):
        bad("episodes are not numbered 0, 1, ... in order")
    starts = np.flatnonzero(new)
    expected_step = np.arange(n) - np.repeat(starts, np.diff(np.r_[starts, n]))
    if not np.array_equal(step, expected_step):
        bad("steps do not count 0, 1, ... within each episode")
    last = np.r_[new[1:], True]
    term, trunc = a["terminated"], a["truncated"]
    if np.any(term & trunc):
        bad(f"{int((term & trunc).sum())} steps are flagged both terminated and truncated")
    if np.any((term | trunc) != last):
        bad("an episode does not end in exactly one terminated or truncated step")
    if a["obs"].shape != a["next_obs"].shape:
        bad("obs and next_obs have different sizes")
    inner = ~last[:-1]
    if inner.any() and not np.array_equal(a["next_obs"][:-1][inner], a["obs"][1:][inner]):
        bad("next_obs[t] differs from obs[t+1] inside an episode (misaligned observations)")
    if np.any((a["action"] < 0) | (a["action"] > 3)):
        bad("actions outside 0..3")
    if not np.all(np.isfinite(a["reward"])) or not np.all(np.isfinite(a["obs"])):
        bad("non-finite rewards or observations")


def episode_stats(table: pa.Table, max_steps: int | None = None) -> dict[str, Any]:
    """Counts, the behaviour's success rate and its mean undiscounted return per episode.

    With ``max_steps`` (the step limit), a truncated episode shorter than it was cut by the end of logging, not
    failed: such episodes are counted (``cut_by_end_of_log``) but left out of the success rate and the mean return,
    which are over the *finished* episodes (target reached or step limit). ``reached_of_all`` counts the cut ones as
    failures: the two bracket the behaviour's true success when a log is short next to the step limit."""
    a = arrays(table)
    ep = a["episode"]
    returns = np.bincount(ep, weights=a["reward"].astype(np.float64))
    lengths = np.bincount(ep)
    n_ep = len(lengths)
    last = np.r_[ep[1:] != ep[:-1], True]
    term_ep = a["terminated"][last]
    cut = a["truncated"][last] & (lengths < max_steps) if max_steps else np.zeros(n_ep, bool)
    done = ~cut
    n_done = int(done.sum())
    return {
        "steps": int(len(ep)),
        "episodes": int(n_ep),
        "terminated": int(term_ep.sum()),
        "truncated": int(a["truncated"].sum()),
        "cut_by_end_of_log": int(cut.sum()),
        "success_rate": float(term_ep[done].sum() / max(1, n_done)),
        "reached_of_all": float(term_ep.sum() / max(1, n_ep)),
        "mean_return": float(returns[done].mean()) if n_done else 0.0,
        "mean_length": float(lengths[done].mean()) if n_done else 0.0,
        "obs_dim": int(a["obs"].shape[1]),
        "mean_reward": float(a["reward"].mean()),
    }
