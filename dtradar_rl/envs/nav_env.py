"""The gymnasium environment of a dataset (one robot); its ids are :mod:`dtradar_rl.envs.registration`."""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, InvalidCoordinatesError
from dtradar_rl.task.grid_mdp import ACTIONS, GridMDP, MovingGridMDP, check_max_steps
from dtradar_rl.task.noise import NOISE_SEED_OFFSET, NoiseModel, RadioNoise, noise_model
from dtradar_rl.task.observations import Normalizer, build_observations, check_preset
from dtradar_rl.task.rewards import check_reward, potential_kind, reward_fn
from dtradar_rl.task.twins import load_dataset


class InvalidActionError(DtradarError, ValueError):
    """An action that is not one of the environment's moves (gymnasium raises on invalid actions)."""


#: The keys ``reset(options=...)`` reads: both cells together, as ``(ix, iy)`` integer pairs, and ``t0``, the start
#: snapshot of a moving twin (with or without the cells).
RESET_OPTIONS = ("start", "target", "t0")
PAIR_OPTIONS = ("start", "target")
CELL_FORM = "a pair of integers (ix, iy), e.g. (3, 2)"


def parse_snapshot(value, snapshots: int) -> int:
    """The reset option ``t0`` as a snapshot index in ``0 .. snapshots - 1``, or :class:`InvalidCoordinatesError`
    naming the key (a fraction, NaN, a bool, a string, a sequence, or a snapshot the twin does not have)."""
    whole = isinstance(value, numbers.Integral) or (
        isinstance(value, numbers.Real) and math.isfinite(value) and float(value).is_integer()
    )
    if isinstance(value, (bool, np.bool_)) or not whole:
        raise InvalidCoordinatesError(
            f"reset option 't0' is {value!r}, not a snapshot index",
            hint=f"pass t0=an integer in 0..{snapshots - 1}",
        )
    if not 0 <= int(value) < snapshots:
        what = "a static twin has one snapshot, 0" if snapshots == 1 else f"this twin has snapshots 0..{snapshots - 1}"
        raise InvalidCoordinatesError(
            f"reset option 't0' is {int(value)}: {what}", hint=f"pass t0 in 0..{snapshots - 1}"
        )
    return int(value)


def parse_cell(key: str, value, nx: int, ny: int) -> tuple[int, int]:
    """``value`` of the option ``key`` as an ``(ix, iy)`` cell inside an ``nx`` x ``ny`` grid, or
    :class:`InvalidCoordinatesError` naming the key and the accepted form (a fraction, NaN, a bool, a string, a
    wrong length or a cell outside the grid)."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise InvalidCoordinatesError(
            f"reset option {key!r} is {value!r}, not a cell",
            hint=f"pass {key}={CELL_FORM}, inside the {nx} x {ny} grid",
        )
    items = list(np.asarray(value, dtype=object).ravel()) if isinstance(value, np.ndarray) else list(value)
    cell = []
    for v in items:
        if isinstance(v, (bool, np.bool_)):
            cell = None
            break
        if isinstance(v, numbers.Integral):
            cell.append(int(v))
        elif isinstance(v, numbers.Real) and math.isfinite(v) and float(v).is_integer():
            cell.append(int(v))  # 3.0 is the cell 3; 2.5 or NaN is no cell
        else:
            cell = None
            break
    if cell is None or len(cell) != 2:
        raise InvalidCoordinatesError(
            f"reset option {key!r} is {value!r}, not a cell",
            hint=f"pass {key}={CELL_FORM}, inside the {nx} x {ny} grid",
        )
    ix, iy = cell
    if not (0 <= ix < nx and 0 <= iy < ny):
        raise InvalidCoordinatesError(
            f"reset option {key!r} is ({ix}, {iy}), outside the {nx} x {ny} grid",
            hint=f"pass {key}=(ix, iy) with 0 <= ix < {nx} and 0 <= iy < {ny}",
        )
    return ix, iy


class DtradarNavEnv(gym.Env):
    """
    ## Description
    A robot navigates a grid of cells of a digital twin from a start cell to a target cell, observing only the
    radio features that the ray tracer computed for its cell (DT-RaDaR, arXiv 2411.12284). Each free cell of the
    per-cell table is a state; blocked cells (obstacles, buildings) cannot be entered.

    ## Actions
    ``Discrete(4)``: ``0: X-`` (one cell towards -x), ``1: X+``, ``2: Y-``, ``3: Y+``. A move into a blocked cell
    or off the grid is a collision: the robot stays where it was. With ``wait_action=True``: ``Discrete(5)``, and
    ``4: wait`` stays on the cell (never a collision; on a moving twin still a mover hit when a mover walks onto the
    robot; rewarded as a step that ends where it began, without the collision penalty).

    ## Moving twins
    On a moving twin (snapshots in time, :mod:`dtradar_rl.task.grid_mdp`) step ``n`` of an episode is in snapshot
    ``(t0 + n) mod T``: a move into a cell a mover covers at the next snapshot is a collision too (the robot stays,
    ``info["mover_collision"]``), a mover walking onto the robot is a *mover hit* (the robot stays,
    ``info["mover_hit"]``, charged the collision penalty), and the robot observes its cell (and neighbours) as they
    are in its snapshot. Without the wait action the robot waits only by bumping.

    ## Observations
    **Privileged** (:mod:`dtradar_rl.task.sensing`): every preset holds the robot's exact ``x, y``, and ``neighbors``
    the radio of the four neighbouring cells read from the twin being navigated, which a robot's receiver could not
    measure. For what a robot with a radio receiver observes, use the honest-sensing env
    (:class:`~dtradar_rl.envs.honest_gym.HonestGymEnv`, ids ``dtradar/<scene>-<variant>-v0``). This env's ids say
    so: ``dtradar/<scene>-<variant>-privileged-v0``.
    ``Box(low, high, (D,), float32)`` (bounds: the range of the lookup tables), z-scored features of the
    chosen preset (:mod:`dtradar_rl.task.observations`):
    ``paper`` (D = 10: x, y, AoA az/zen, AoD az/zen, coefficient real/imag, delay, phase; no target),
    ``goal`` (D = 12: paper + target x, y), ``neighbors`` (D = 48: paper + radio features and a has-radio flag of
    the four neighbouring cells + target x, y). ``neighbors`` with ``sense_radius`` R > 1 adds, before the target,
    the has-radio flags of the cells at Manhattan distance 2..R in this snapshot and in the one before
    (``2 · (2R(R+1) - 4)`` columns). ``clock="sincos"`` appends the phase of a moving twin's schedule, ``cos`` and
    ``sin`` of ``2π t / T``, after them (:mod:`dtradar_rl.task.clock`).

    ## Rewards
    Chosen by name (:mod:`dtradar_rl.task.rewards`). ``paper``: ``-(dx² + dy²)`` (cell units, distance to the target
    after the move) ``+ 5000`` on reaching the target ``- 5000`` on a collision. ``scaled``: the same terms divided to
    order one. ``euclidean`` / ``geodesic``: potential-based shaping with the straight-line / breadth-first
    distance, ``+1`` on reaching the target, ``-1`` on a collision.

    ## Starting State
    Start and target are drawn uniformly at random among connected free cells (distinct), or given with
    ``reset(options={"start": (ix, iy), "target": (ix, iy)})``: both keys, each a pair of integers (a float only when
    whole) naming distinct, free, connected cells; anything else (a fraction, NaN, another length, an unknown key)
    is an :class:`~dtradar_data.core.errors.InvalidCoordinatesError` naming the key, before the episode changes.
    On a moving twin ``t0`` (an integer in 0..T-1, with or without the cells) is the start snapshot, default drawn
    uniformly among the snapshots in which the start is free; the start must be free then. A static twin has one
    snapshot: ``t0`` may only be 0.

    ## Episode End
    Termination: the robot reaches the target. Truncation: ``max_steps`` steps taken (default ``4 · (nx + ny)``).

    ## Arguments
    ``dataset``: a :class:`dtradar_data.Dataset` or a dataset name (``"cubicle/blueprint"``,
    ``"synthetic/blueprint"``); ``obs``: observation preset (default ``"goal"``); ``reward``: reward name (default
    ``"paper"``); ``max_steps``: step limit, a positive int (None or 0: the default; anything else is an
    :class:`~dtradar_data.core.errors.InvalidSettingError`); ``normalizer``: feature statistics (default: fitted on
    ``dataset``; pass the training twin's when evaluating on another twin); ``render_mode``: ``None``, ``"ansi"`` or
    ``"rgb_array"``; ``noise``: measurement noise level (``"none"``, ``"realistic"``, ``"2x"``; see
    :mod:`dtradar_rl.task.noise`), drawn anew at every reset and step from a generator seeded by ``reset(seed=...)``;
    ``sense_radius``: cells sensed around the robot (1: the four neighbours; more: ``neighbors`` only, see
    :mod:`dtradar_rl.task.observations`); ``clock``: ``"none"`` or ``"sincos"`` (the schedule's phase);
    ``wait_action``: add action 4, wait; ``mover_penalty``: the collision penalty of a step that meets a mover, in
    units of the reward's (default 1; see :mod:`dtradar_rl.envs.batched_moves`).

    ## Info
    ``cell`` and ``target`` (ix, iy), ``collision``, ``is_success``, ``distance`` (breadth-first steps from the
    current cell to the target); on a moving twin also ``t`` (the snapshot), ``mover_collision``, ``mover_hit``, and
    ``distance`` is the space-time one (fewest steps from the cell at this snapshot, waiting allowed; -1: never).

    ## Version History
    * v0: initial version; the ``noise`` argument (default ``"none"``: unchanged) and ``sense_radius`` (default 1:
      unchanged), ``clock`` (default ``"none"``) and ``wait_action`` (default False: unchanged) added later.
    """

    metadata = {"render_modes": ["ansi", "rgb_array"], "render_fps": 4}

    def __init__(
        self,
        dataset: Dataset | str = "synthetic/blueprint",
        obs: str = "goal",
        reward: str = "paper",
        max_steps: int | None = None,
        normalizer: Normalizer | dict | None = None,
        render_mode: str | None = None,
        noise: str | NoiseModel = "none",
        sense_radius: int = 1,
        clock: str = "none",
        wait_action: bool = False,
        mover_penalty: float = 1.0,
    ):
        ds = load_dataset(dataset) if isinstance(dataset, str) else dataset
        self.dataset_name = ds.name
        self.obs_preset, self.reward_name = check_preset(obs), check_reward(reward)
        if isinstance(normalizer, dict):
            normalizer = Normalizer.from_dict(normalizer)
        self.normalizer = normalizer or Normalizer.fit(ds)
        self.mdp = GridMDP.from_dataset(ds)
        self.table = build_observations(ds, obs, self.normalizer, sense_radius, clock)
        self.moving = isinstance(self.mdp, MovingGridMDP)
        self.snapshots = self.mdp.snapshots if self.moving else 1
        self.max_steps = check_max_steps(max_steps) or self.mdp.max_steps
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InvalidCoordinatesError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.wait_action = bool(wait_action)
        self.mover_penalty = float(mover_penalty)  # dtradar_rl.envs.batched_moves: a training setting
        self.action_space = spaces.Discrete(len(ACTIONS) + int(self.wait_action))
        # Observations come from the lookup tables, so their exact range is known: bound the space by it.
        lows = np.concatenate([self.table.cell_part.min(0), self.table.target_part.min(0)]).astype(np.float32)
        highs = np.concatenate([self.table.cell_part.max(0), self.table.target_part.max(0)]).astype(np.float32)
        if noise_model(noise).is_zero:
            self.observation_space = spaces.Box(lows, highs, (self.table.dim,), np.float32)
        else:  # a noisy measurement can fall outside the table's range
            self.observation_space = spaces.Box(-np.inf, np.inf, (self.table.dim,), np.float32)
        self._cell = self._target = 0
        self._steps = 0
        self._t = 0  # the snapshot (moving twins)
        self._dist: np.ndarray | None = None
        self._st_dist: np.ndarray | None = None  # int32[T, cells] space-time distances (moving twins)
        model = noise_model(noise)
        self.noise = None if model.is_zero else RadioNoise(model, self.table, self.normalizer, torch.device("cpu"))
        self.noise_gen = torch.Generator()
        self.noise_gen.manual_seed(NOISE_SEED_OFFSET)
        self._errors = None

    def _observe(self) -> np.ndarray:
        t = self._t if self.moving else None
        obs = self.table.observe(self._cell, self._target, t)
        if self.noise is None:
            return obs
        cells = torch.as_tensor([self._cell if t is None else self.table.row(self._cell, t)])
        return self.noise.apply(torch.from_numpy(obs[None]), cells, self._errors)[0].numpy()

    def _measure(self) -> None:
        """A new measurement at the robot's cell: fresh noise errors (nothing without noise)."""
        if self.noise is not None:
            self._errors = self.noise.draw(1, self.noise_gen)

    # ---------------------------------------------------------------------------------------------------------
    def _cell_of(self, key: str, value) -> int:
        ix, iy = parse_cell(key, value, self.mdp.nx, self.mdp.ny)
        c = self.mdp.cell(ix, iy)
        if self.mdp.blocked.ravel()[c]:
            raise InvalidCoordinatesError(
                f"reset option {key!r}: cell ({ix}, {iy}) is blocked in {self.dataset_name}", hint="pick a free cell"
            )
        return c

    def _episode_from(self, options) -> tuple[tuple[int, int] | None, int | None]:
        """The (start, target) cells that ``reset(options=...)`` asks for (None for a random pair) and its ``t0``
        (None: drawn); every key and value is checked before the episode changes."""
        if options is None:
            return None, None
        if not isinstance(options, Mapping):
            raise InvalidCoordinatesError(
                f"reset options must be a dict, got {type(options).__name__}",
                hint="pass options={'start': (ix, iy), 'target': (ix, iy)}, or none for a random pair",
            )
        unknown = [k for k in options if k not in RESET_OPTIONS]
        if unknown:
            raise InvalidCoordinatesError(
                f"unknown reset option(s) {', '.join(map(repr, unknown))}",
                hint=f"the env reads {' and '.join(map(repr, PAIR_OPTIONS))}, each {CELL_FORM}, and 't0' (the start "
                "snapshot of a moving twin)",
            )
        t0 = parse_snapshot(options["t0"], self.snapshots) if "t0" in options else None
        pair = self._pair_from({k: v for k, v in options.items() if k != "t0"})
        if pair is not None and t0 is not None and self.moving and not self.mdp.free_at(t0)[pair[0]]:
            raise InvalidCoordinatesError(
                f"reset option 'start': cell {tuple(int(v) for v in self.mdp.xy(pair[0]))} is covered by a mover at "
                f"snapshot t0={t0} in {self.dataset_name}",
                hint="pick a start that is free at t0, or another t0",
            )
        return pair, t0

    def _pair_from(self, options) -> tuple[int, int] | None:
        """The (start, target) cells of ``options`` (a dict without ``t0``), None for a random pair."""
        if not options:
            return None
        missing = [k for k in PAIR_OPTIONS if k not in options]
        if missing:
            raise InvalidCoordinatesError(
                f"reset options give {next(k for k in PAIR_OPTIONS if k in options)!r} without {missing[0]!r}",
                hint="pass both 'start' and 'target', each " + CELL_FORM,
            )
        start, target = self._cell_of("start", options["start"]), self._cell_of("target", options["target"])
        if start == target:
            raise InvalidCoordinatesError(
                f"reset options: start and target are the same cell {self.mdp.xy(start)}",
                hint="pick two different cells",
            )
        if not self.mdp.connected(start, target):
            raise InvalidCoordinatesError(
                f"start {tuple(int(v) for v in self.mdp.xy(start))} and target "
                f"{tuple(int(v) for v in self.mdp.xy(target))} are not connected in {self.dataset_name}",
                hint="pick a target the start can reach",
            )
        return start, target

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # checked first: a refused reset leaves the episode and the seed as they were
        pair, t0 = self._episode_from(options)
        super().reset(seed=seed)
        if seed is not None:
            self.noise_gen.manual_seed(int(seed) + NOISE_SEED_OFFSET)
        if self.moving and pair is None and t0 is not None:  # a random pair whose start is free at t0
            start, target = self._pair_free_at(t0)
        else:
            start, target = pair if pair is not None else self.mdp.sample_pairs(1, self.np_random)[0]
        self._cell, self._target, self._steps = int(start), int(target), 0
        self._dist = self.mdp.bfs_distances(self._target)
        if self.moving:
            self._t = int(t0) if t0 is not None else int(self.mdp.draw_t0([self._cell], self.np_random)[0])
            self._st_dist = self.mdp.space_time_distances(self._target)
        self._measure()
        return self._observe(), self._info(False)

    def _pair_free_at(self, t0: int) -> tuple[int, int]:
        """A random connected pair whose start is free at snapshot ``t0`` (moving twins)."""
        for _ in range(1000):
            start, target = self.mdp.sample_pairs(1, self.np_random)[0]
            if self.mdp.free_at(t0)[start]:
                return int(start), int(target)
        raise InvalidCoordinatesError(
            f"reset option 't0': movers cover every start cell drawn at snapshot {t0}", hint="pass another t0"
        )

    def _potential(self, cell: int) -> float:
        if potential_kind(self.reward_name) == "geodesic":
            return float(self._dist[cell])
        return float(np.sqrt(self.mdp.d2(cell, self._target)))

    def step(self, action):
        # Discrete.contains takes Python and numpy integers and 0-d integer arrays, and refuses 1.5 and '2' that
        # int() would have turned into moves; a bool is an int to Python but never a meant action.
        if isinstance(action, (bool, np.bool_)) or not self.action_space.contains(action):
            raise InvalidActionError(
                f"action {action!r} ({type(action).__name__}) is not an integer in 0..{self.action_space.n - 1} "
                f"({', '.join(f'{i} = {a}' for i, a in enumerate(ACTIONS + ('wait',) * self.wait_action))})",
                hint="pass an int, a numpy integer or a 0-d integer array",
            )
        if self._dist is None:
            raise InvalidActionError("step() called before reset()", hint="call env.reset() first")
        action = int(action)
        before = self._cell
        if self.moving:
            self._cell, self._t, wall, mover_collision, mover_hit = self.mdp.step_at(before, self._t, action)
            collision = wall or mover_collision
            penalised = collision or mover_hit
            if self.mover_penalty != 1.0:
                penalised = self.mover_penalty if (mover_collision or mover_hit) else float(penalised)
        else:
            self._cell, collision = self.mdp.step(before, action)
            penalised = collision
        self._steps += 1
        reached = self._cell == self._target
        shaped = potential_kind(self.reward_name) is not None
        reward = reward_fn(
            self.reward_name,
            d2_after=float(self.mdp.d2(self._cell, self._target)),
            pot_before=self._potential(before) if shaped else 0.0,
            pot_after=self._potential(self._cell) if shaped else 0.0,
            collision=penalised,
            reached=reached,
            diag2=self.mdp.diag2,
        )
        truncated = self._steps >= self.max_steps and not reached
        self._measure()
        obs = self._observe()
        info = self._info(collision)
        if self.moving:
            info.update(mover_collision=bool(mover_collision), mover_hit=bool(mover_hit))
        return obs, float(np.float32(reward)), bool(reached), bool(truncated), info

    def _info(self, collision: bool) -> dict:
        if self.moving:
            known = self._st_dist is not None
            return {
                "cell": tuple(int(v) for v in self.mdp.xy(self._cell)),
                "target": tuple(int(v) for v in self.mdp.xy(self._target)),
                "collision": bool(collision),
                "is_success": self._cell == self._target,
                "distance": int(self._st_dist[self._t, self._cell]) if known else -1,
                "t": int(self._t),
                "mover_collision": False,
                "mover_hit": False,
            }
        return {
            "cell": tuple(int(v) for v in self.mdp.xy(self._cell)),
            "target": tuple(int(v) for v in self.mdp.xy(self._target)),
            "collision": bool(collision),
            "is_success": self._cell == self._target,
            "distance": int(self._dist[self._cell]) if self._dist is not None else -1,
        }

    def render(self):
        if self.render_mode is None:
            return None
        grid = np.where(self.mdp.blocked, "#", ".").astype("<U1")
        movers = self.mdp.mover[self._t].reshape(self.mdp.blocked.shape) if self.moving else None
        if movers is not None:
            grid[movers] = "M"
        (x, y), (tx, ty) = self.mdp.xy(self._cell), self.mdp.xy(self._target)
        grid[ty, tx], grid[y, x] = "T", "R"
        if self.render_mode == "ansi":
            return "\n".join("".join(row) for row in grid[::-1]) + "\n"  # +y up
        img = np.full((*self.mdp.blocked.shape, 3), 255, np.uint8)
        img[self.mdp.blocked] = (60, 60, 60)
        if movers is not None:
            img[movers] = (230, 140, 0)
        img[ty, tx], img[y, x] = (0, 170, 0), (220, 0, 0)
        return np.repeat(np.repeat(img[::-1], 8, 0), 8, 1)
