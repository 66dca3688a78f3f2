"""Agents with memory: an egocentric map of what the robot has sensed so far, appended to its observation.

A policy that sees only its four neighbours forgets a dead end the moment it turns away from it, walks back in and
oscillates (the failure behind most of the blueprint -> dynamic gap). Here each robot keeps, for the current
episode, two maps of the grid:

* ``sensed``: cells it has sensed as occupied: a neighbour whose radio features are missing (has-radio flag 0 in the
  ``neighbors`` observation: no path from any transmitter; an augmented obstacle reads the same, see
  :mod:`dtradar_rl.envs.batched`) or off the grid;
* ``visited``: cells it has stood on;
* ``bumped`` (with ``memory_bumps``): cells it tried to move into and could not: the feedback of a bumper or of
  wheel odometry. A free street cell that no ray of any transmitter reached reads as "no radio" like an obstacle,
  so only a bump tells the two apart (a twin with several transmitters leaves fewer such cells);
* ``visits`` (with ``memory_visits``): how many times it has stood on each cell; the observation gets one more
  column, ``visits_here``: the earlier stands on the cell it stands on now (capped at :data:`VISITS_CAP`). A
  policy that finds itself back on a cell it already left twice is in a loop: the default agent then takes a
  random move (``escape_after``, :class:`~dtradar_rl.agents.policy.Policy`).

The observation is the ``neighbors`` one followed by a ``(2R+1) x (2R+1)`` window of each map centred on the robot
(``memory_radius = R``; cells off the grid read as sensed). Everything the memory holds is derived from earlier
observations; the window only keeps them. The ``neighbors`` observation it extends is privileged (the robot's
``x, y`` and its neighbours' radio; :mod:`dtradar_rl.task.sensing`), so the memory agents are too. With a wider sensing
radius (:mod:`dtradar_rl.task.observations`) the ring's flags sit between the ``neighbors`` columns and the target's,
and ``sensed`` still takes only the four neighbours: the map keeps what it sensed for the whole episode, so a mover
seen passing 2..R cells away would stay in it as an obstacle long after it has gone (the ring is in the observation
itself, now and a snapshot before).

:class:`MemoryNavEnv` (batched torch) and :class:`MemoryGymEnv` (gymnasium) share one :class:`MemoryLayout` of index
tables and are tested to agree step for step.
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.task.grid_mdp import ACTION_DELTAS, GridMDP
from dtradar_rl.task.observations import (
    PAPER_COLUMNS,
    RADIO_FEATURES,
    Normalizer,
    ObservationTable,
    build_observations,
)

CHANNELS: tuple[str, ...] = ("sensed", "visited")
BUMP_CHANNELS: tuple[str, ...] = CHANNELS + ("bumped",)
VISITS_CAP = 8


def flag_columns() -> list[int]:
    """Columns of the four has-radio flags in a ``neighbors`` observation, in action order."""
    k = len(RADIO_FEATURES) + 1
    return [len(PAPER_COLUMNS) + a * k + k - 1 for a in range(4)]


class MemoryLayout:
    """Index tables of the memory maps of one grid, padded by ``radius`` cells on every side (the padding reads as
    sensed, so the window never needs a bounds check)."""

    def __init__(self, nx: int, ny: int, radius: int, bumps: bool = False, visits: bool = False):
        if radius < 1:
            raise InvalidCoordinatesError(f"memory radius must be >= 1, got {radius}")
        self.nx, self.ny, self.radius = nx, ny, radius
        self.channels = BUMP_CHANNELS if bumps else CHANNELS
        self.visits = visits
        r, pw = radius, nx + 2 * radius
        self.padded_cells = pw * (ny + 2 * radius)
        iy, ix = np.divmod(np.arange(nx * ny), nx)
        #: ``int64[cells]``: each cell's index in the padded map
        self.pad = (iy + r) * pw + (ix + r)
        #: ``int64[cells, 4]``: each neighbour's padded index, in action order (off-grid ones land in the padding)
        self.neighbor = self.pad[:, None] + ACTION_DELTAS[None, :, 1] * pw + ACTION_DELTAS[None, :, 0]
        d = np.arange(-r, r + 1)
        #: ``int64[cells, (2R+1)^2]``: the window around each cell, rows of +y
        self.window = self.pad[:, None] + (d[:, None] * pw + d[None, :]).ravel()[None, :]
        init = np.ones((ny + 2 * r, pw), np.float32)
        init[r : r + ny, r : r + nx] = 0.0
        #: ``float32[padded]``: an empty ``sensed`` map (only the padding set)
        self.sensed_init = init.ravel()

    @property
    def dim(self) -> int:
        return len(self.channels) * (2 * self.radius + 1) ** 2 + int(self.visits)

    def stacked_window(self) -> np.ndarray:
        """``int64[cells, dim]``: each cell's memory observation as indices into the maps laid end to end (the
        channels in order, then the visit counts), so one gather reads it; the last column (with ``visits``) is
        the cell's own visit count, still to be turned into ``visits_here``."""
        p = self.padded_cells
        cols = [self.window + c * p for c in range(len(self.channels))]
        if self.visits:
            cols.append(self.pad[:, None] + len(self.channels) * p)
        return np.concatenate(cols, 1)

    @property
    def names(self) -> tuple[str, ...]:
        r = self.radius
        return tuple(
            f"{ch}[{dx:+d},{dy:+d}]" for ch in self.channels for dy in range(-r, r + 1) for dx in range(-r, r + 1)
        ) + (("visits_here",) if self.visits else ())


def _require_neighbors(obs_table: ObservationTable) -> None:
    if obs_table.preset != "neighbors":
        raise InvalidCoordinatesError(
            f"a memory agent senses obstacles through the 'neighbors' observation, got {obs_table.preset!r}",
            hint="use --obs neighbors",
        )


class _Map:
    """A memory map of :class:`MemoryNavEnv`: a view of its channel in the stacked ``_maps`` (None when the env
    keeps no such map). Assigning copies into that channel, so state restored by ``setattr`` (a resumed training
    run, :attr:`MemoryNavEnv.state_keys`) lands where the observation reads it."""

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, env, owner=None):
        if env is None:
            return self
        channel = env._channel.get(self.name)
        return None if channel is None else env._maps[:, channel]

    def __set__(self, env, value) -> None:
        env._maps[:, env._channel[self.name]] = value


class MemoryNavEnv(BatchedNavEnv):
    """:class:`~dtradar_rl.envs.batched.BatchedNavEnv` whose observation carries each robot's memory window.

    The maps of all robots live in one ``float32[num_envs, maps, padded cells]`` tensor, so a robot's whole memory
    window (every map, and its visit count) is a single gather: a batch-1 decision's observation is a handful of
    tensor ops (each ~2 us of dispatch, far more than the arithmetic)."""

    sensed, visited, bumped, visits = _Map(), _Map(), _Map(), _Map()

    def __init__(
        self,
        mdp: GridMDP,
        obs_table: ObservationTable,
        num_envs: int,
        *,
        memory_radius: int = 5,
        memory_bumps: bool = False,
        memory_visits: bool = False,
        **kw,
    ):
        _require_neighbors(obs_table)
        self.layout = MemoryLayout(mdp.nx, mdp.ny, memory_radius, bumps=memory_bumps, visits=memory_visits)
        super().__init__(mdp, obs_table, num_envs, **kw)
        lay, dev = self.layout, self.device
        t = lambda a: torch.as_tensor(a, device=dev)
        self._pad, self._nbr = t(lay.pad), t(lay.neighbor)
        self._flags = torch.as_tensor(flag_columns(), device=dev)
        names = lay.channels + (("visits",) if memory_visits else ())
        self._channel = {name: c for c, name in enumerate(names)}
        #: ``float32[maps, padded]``: an empty memory (only the padding of ``sensed`` set)
        self._maps_init = torch.zeros((len(names), lay.padded_cells), device=dev)
        self._maps_init[0] = t(lay.sensed_init)
        self._maps = self._maps_init.repeat(self.num_envs, 1, 1)
        self._maps_flat = self._maps.view(self.num_envs, -1)  # the same storage, one row per robot
        self._window = t(lay.stacked_window())
        self._one = torch.ones((), device=dev)

    @classmethod
    def from_dataset(
        cls,
        ds: Dataset,
        num_envs: int,
        *,
        obs: str = "neighbors",
        normalizer: Normalizer | None = None,
        sense_radius: int = 1,
        clock: str = "none",
        **kwargs,
    ) -> MemoryNavEnv:
        normalizer = normalizer or Normalizer.fit(ds)
        table = build_observations(ds, obs, normalizer, sense_radius, clock)
        return cls(GridMDP.from_dataset(ds), table, num_envs, **kwargs)

    @property
    def obs_dim(self) -> int:
        return self.obs_table.dim + self.layout.dim

    @property
    def obs_names(self) -> tuple[str, ...]:
        return self.obs_table.names + self.layout.names

    @property
    def state_keys(self) -> tuple[str, ...]:
        extra = (("bumped",) if self.bumped is not None else ()) + (("visits",) if self.visits is not None else ())
        return super().state_keys + ("sensed", "visited") + extra

    def _sense(self, idx: torch.Tensor | None = None) -> None:
        """Record what robots ``idx`` (default all) sense from where they stand now."""
        base = super().observe()
        cells = self.cell
        if idx is not None:
            base, cells = base[idx], cells[idx]
        rows = torch.arange(self.num_envs, device=self.device) if idx is None else idx
        occupied = (base[:, self._flags] < 0.5).float()  # [k, 4]
        nbr = self._nbr[cells]
        self.sensed[rows[:, None], nbr] = torch.maximum(self.sensed[rows[:, None], nbr], occupied)
        self.visited[rows, self._pad[cells]] = 1.0
        if self.visits is not None:
            self.visits[rows, self._pad[cells]] += 1.0

    def reset_where(self, mask: torch.Tensor, starts=None, targets=None, t0=None) -> None:
        super().reset_where(mask, starts=starts, targets=targets, t0=t0)
        idx = torch.nonzero(mask.to(self.device), as_tuple=True)[0]
        if idx.numel():
            self._maps[idx] = self._maps_init
            self._sense(idx)

    def step(self, actions: torch.Tensor):
        before = self.cell
        _, reward, terminated, truncated, info = super().step(actions)
        if self.bumped is not None:  # the bumper: a move that failed marks the cell it aimed at
            hit = torch.nonzero(info["collision"], as_tuple=True)[0]
            a = actions.to(self.device, torch.long)[hit]
            self.bumped[hit, self._nbr[before[hit], a]] = 1.0
        self._sense()
        return self.observe(), reward, terminated, truncated, info

    def memory_window(self) -> torch.Tensor:
        win = self._maps_flat.gather(1, self._window[self.cell])
        if self.layout.visits:  # the visit count of the cell stood on -> the earlier stands, capped
            win.select(1, -1).sub_(self._one).clamp_(0.0, VISITS_CAP)  # (a tensor 1: no scalar to wrap, 1.5 us)
        return win

    def observe(self) -> torch.Tensor:
        if self.noise is None:  # one cat for the table rows and the window (a batch-1 decision is mostly op overhead)
            return torch.cat([*self._table_rows(), self.memory_window()], 1)
        return torch.cat([super().observe(), self.memory_window()], 1)


class MemoryGymEnv(DtradarNavEnv):
    """The gymnasium env with the same memory window appended (one robot; numpy)."""

    def __init__(
        self,
        dataset: Dataset | str = "synthetic/blueprint",
        obs: str = "neighbors",
        memory_radius: int = 5,
        memory_bumps: bool = False,
        memory_visits: bool = False,
        **kwargs,
    ):
        super().__init__(dataset, obs=obs, **kwargs)
        _require_neighbors(self.table)
        self.layout = MemoryLayout(self.mdp.nx, self.mdp.ny, memory_radius, bumps=memory_bumps, visits=memory_visits)
        base = self.observation_space
        m = self.layout.dim
        high = np.ones(m, np.float32)
        if memory_visits:
            high[-1] = VISITS_CAP
        self.observation_space = spaces.Box(
            np.concatenate([base.low, np.zeros(m, np.float32)]),
            np.concatenate([base.high, high]),
            (base.shape[0] + m,),
            np.float32,
        )
        self._sensed = self.layout.sensed_init.copy()
        self._visited = np.zeros_like(self._sensed)
        self._bumped = np.zeros_like(self._sensed) if memory_bumps else None
        self._visits = np.zeros_like(self._sensed) if memory_visits else None

    def _sense(self, obs: np.ndarray) -> np.ndarray:
        occupied = (obs[flag_columns()] < 0.5).astype(np.float32)
        nbr = self.layout.neighbor[self._cell]
        self._sensed[nbr] = np.maximum(self._sensed[nbr], occupied)
        here = self.layout.pad[self._cell]
        self._visited[here] = 1.0
        win = self.layout.window[self._cell]
        maps = [self._sensed, self._visited] + ([self._bumped] if self._bumped is not None else [])
        parts = [obs] + [m[win] for m in maps]
        if self._visits is not None:
            self._visits[here] += 1.0
            parts.append(np.clip([self._visits[here] - 1.0], 0.0, VISITS_CAP))
        return np.concatenate(parts).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = super().reset(seed=seed, options=options)
        self._sensed = self.layout.sensed_init.copy()
        self._visited[:] = 0.0
        if self._bumped is not None:
            self._bumped[:] = 0.0
        if self._visits is not None:
            self._visits[:] = 0.0
        return self._sense(obs), info

    def step(self, action):
        before = self._cell
        obs, reward, terminated, truncated, info = super().step(action)
        if self._bumped is not None and info["collision"]:
            self._bumped[self.layout.neighbor[before, int(action)]] = 1.0
        return self._sense(obs), reward, terminated, truncated, info


def batched_env(
    ds: Dataset,
    num_envs: int,
    *,
    memory_radius: int = 0,
    memory_bumps: bool = False,
    memory_visits: bool = False,
    **kwargs,
) -> BatchedNavEnv:
    """A batched env over ``ds``: with memory when ``memory_radius`` > 0 (and a bump map with ``memory_bumps``, the
    visit count with ``memory_visits``), else the plain one."""
    if memory_radius:
        return MemoryNavEnv.from_dataset(
            ds, num_envs, memory_radius=memory_radius, memory_bumps=memory_bumps, memory_visits=memory_visits, **kwargs
        )
    return BatchedNavEnv.from_dataset(ds, num_envs, **kwargs)
