"""The clock observation (``clock``): the phase of the movers' schedule, ``t mod T``, as the robot's observation.

A moving twin is periodic (snapshot ``t`` is the world at ``t · dt_s`` and after ``T - 1`` comes 0), so a robot that
knows the phase can learn where each mover will be. ``clock="sincos"`` appends two columns to every cell-part row of
snapshot ``t``: ``cos(2π t / T)`` and ``sin(2π t / T)`` (not normalised; ``clock_cos``, ``clock_sin``). They go
after every other cell-part column (the transmitters' and the wider ring's), so no fixed column offset moves
(:attr:`~dtradar_rl.task.observations.ObservationTable.ring_columns` counts them).

Why two periodic columns rather than a one-hot of ``t``: the width stays two whatever ``T`` is, so an agent trained
among the movers still acts on its static blueprint (``T = 1``: the constant phase ``(1, 0)``) and on twins of other
periods (a one-hot would need ``T`` columns: 16 on the cubicle, 48 in the meeting room, and one on a blueprint, so a
model would fit only twins of its own ``T``); and neighbouring snapshots, where the walkers are nearly where they
were, read nearly alike. ``"none"`` (the default) adds nothing: the tables are byte for byte the ones without it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from dtradar_data.core.errors import unknown_name

CLOCKS: tuple[str, ...] = ("none", "sincos")
CLOCK_NAMES: dict[str, tuple[str, ...]] = {"none": (), "sincos": ("clock_cos", "clock_sin")}


def check_clock(name: str) -> str:
    """``name`` if it is a known clock (:data:`CLOCKS`), else :class:`~dtradar_data.core.errors.UnknownNameError`."""
    if name not in CLOCKS:
        raise unknown_name("clock", name, CLOCKS)
    return name


def clock_columns(name: str) -> int:
    """The columns clock ``name`` adds to the cell part."""
    return len(CLOCK_NAMES[check_clock(name)])


def with_clock(table: Any, name: str) -> Any:  # an ObservationTable (observations imports this module)
    """``table`` with clock ``name``'s columns appended to its cell part (module docstring); ``"none"``: ``table``."""
    if check_clock(name) == "none":
        return table
    snaps = table.snapshots
    n = table.cell_part.shape[0] // snaps
    angle = 2.0 * np.pi * np.arange(snaps) / snaps
    phase = np.stack([np.cos(angle), np.sin(angle)], 1).astype(np.float32)  # [T, 2]
    dc = table.cell_part.shape[1]
    cell_part = np.concatenate([table.cell_part, np.repeat(phase, n, axis=0)], 1)
    names = table.names[:dc] + CLOCK_NAMES[name] + table.names[dc:]
    return replace(table, cell_part=np.ascontiguousarray(cell_part, np.float32), names=names, clock=name)
