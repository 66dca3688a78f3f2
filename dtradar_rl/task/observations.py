"""What the learnt agents observe: observation presets built by table lookup, and the normaliser stored with a model.

Every preset here is **privileged** (:mod:`dtradar_rl.task.sensing`): it holds the robot's exact ``x, y``, and
``neighbors`` the radio of the four neighbouring cells read from the twin being navigated. What a robot with a radio
receiver observes (its own cell's measurement, proximity, odometry; never its position) is
:mod:`dtradar_rl.task.sensing` and :mod:`dtradar_rl.envs.honest`.

An observation is the concatenation of a part that depends only on the robot's cell and a part that depends only
on the target cell, ``obs = [cell_part[cell], target_part[target]]``, so both environments build it with two
lookups. All features are z-scored with a :class:`Normalizer` (per table column: mean and standard deviation over
the free cells of the *training* dataset with a path); the normaliser is saved in every checkpoint and reused
unchanged on other twins. A missing value (a free cell without any propagation path, or a neighbour that is blocked
or off the grid) becomes 0 after normalisation, i.e. the training mean.

Presets (:data:`OBS_PRESETS`)
-----------------------------
``paper`` (10)      exactly the paper's state: ``x, y`` (cell centre, m), AoA azimuth and zenith, AoD azimuth and
                    zenith (rad), real and imaginary part of the strongest path's coefficient, its delay (s), and
                    its phase φ (rad). The paper names nine quantities but counts ten inputs; the tenth is taken to
                    be the phase φ, which the paper's Module 2 lists among the per-cell outputs. The paper state has
                    **no target**: a policy cannot know where a randomly drawn target is, so with random targets
                    this preset cannot succeed beyond chance. It is kept for the exact reproduction.
``goal`` (12)       ``paper`` + the target's ``x, y`` (m): the goal-conditioned correction.
``neighbors`` (48)  ``paper`` + for each neighbouring cell in action order (X-, X+, Y-, Y+) its 8 radio features
                    (as in ``paper`` without ``x, y``) and a flag that is 1 where the neighbour has radio features
                    (0 = blocked, off the grid or no path) + the target's ``x, y``. An agent can sense an obstacle
                    it has never seen (the dynamic twin) from the missing radio features next to it.

Wider sensing (``sense_radius`` R > 1, ``neighbors`` only)
---------------------------------------------------------
The four neighbours sense a mover only once it is next to the robot, and a walker of the ray-traced rooms moves 2-3
cells per snapshot. With ``sense_radius=R`` the cell part gets, after its 46 columns (so the ``neighbors`` layout that
the memory env, the shield, :class:`~dtradar_rl.agents.planner.MoverGuard` and the noise read stays where it is),
the has-radio flag of every cell at Manhattan distance 2..R (:func:`ring_offsets`: ``4 * d`` cells at distance
``d``), first in the robot's snapshot ``t`` (``has_radio[dx,dy]``), then in the snapshot before, ``(t - 1) mod T``
(``has_radio_before[dx,dy]``): two frames show a memoryless network which way a mover walks. At an episode's first
step the snapshot before is the periodic world's, which is what a sensor running before the episode saw. On a
static twin both blocks are the static map (a static and a moving twin's observations keep one width, so one agent
acts on both). The flags are 0/1 like the neighbours' (not normalised). R = 1 adds nothing: the tables are the
ones above, byte for byte.

The clock (``clock="sincos"``, any preset: :mod:`dtradar_rl.task.clock`) appends the phase of the movers' schedule,
``cos`` and ``sin`` of ``2π t / T``, as the cell part's last two columns, after the ring's (a static twin: ``(1, 0)``).

Several transmitters (a twin with ``K > 1``, ``Dataset.transmitters``)
-----------------------------------------------------------------------
Transmitter 0's features keep every column above. For each further transmitter ``k = 1..K-1`` the cell part gets,
after the preset's columns (10, or 46 with ``neighbors``) and before the wider ring's flags (so every offset above,
:attr:`ObservationTable.ring_columns` included, stays where it is), the robot cell's 8 radio features of transmitter
``k`` (``tx{k}_aoa_az_rad`` ... ``tx{k}_phase_rad``, z-scored by the normaliser like the others, 0 where missing)
and a flag ``tx{k}_has_path`` (1: transmitter ``k`` has a path to the cell; not normalised). Dimensions:
``paper`` 10 + 9(K-1), ``goal`` 12 + 9(K-1), ``neighbors`` 48 + 9(K-1) + 2(2R(R+1) - 4) (:func:`obs_dim`).

Every has-radio flag (the neighbours', the ring's, :attr:`ObservationTable.has_radio`) means *free and a path from
at least one transmitter*: a street that only transmitter 1 reaches reads as free, not as a wall, which is why a
twin has several transmitters. A neighbour carries transmitter 0's features only (0 where transmitter 0 does not
reach it, its flag still 1 when another one does): the flag is what the agent, the shield, the memory and the
planner read of a neighbour, and the robot learns every transmitter's features on the cells it stands on, so the
neighbours' copies would cost 9 columns per neighbour and transmitter (36 per transmitter) for a feature no
consumer reads. The normaliser's columns (:func:`observation_columns`) name the transmitters, so a model keeps
their number: a twin with another count is refused (:func:`check_transmitters`). K = 1 changes nothing: the tables
are the ones above, byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError, unknown_name
from dtradar_data.core.schema import tx_column
from dtradar_rl.task.clock import clock_columns, with_clock
from dtradar_rl.task.grid_mdp import ACTION_DELTAS

#: The paper's ten inputs, in order (see the module docstring for the tenth).
PAPER_COLUMNS: tuple[str, ...] = (
    "x_m",
    "y_m",
    "aoa_az_rad",
    "aoa_zen_rad",
    "aod_az_rad",
    "aod_zen_rad",
    "a_re",
    "a_im",
    "tau_s",
    "phase_rad",
)
RADIO_FEATURES: tuple[str, ...] = PAPER_COLUMNS[2:]
OBS_PRESETS: tuple[str, ...] = ("paper", "goal", "neighbors")
OBS_DIMS: dict[str, int] = {"paper": 10, "goal": 12, "neighbors": 10 + 4 * (len(RADIO_FEATURES) + 1) + 2}
#: The flag column of transmitter ``k >= 1`` (:func:`tx_names`).
HAS_PATH = "has_path"


def radio_columns(k: int) -> tuple[str, ...]:
    """The table (and normaliser) columns of transmitter ``k``'s radio features: :data:`RADIO_FEATURES` for 0."""
    return tuple(tx_column(c, k) for c in RADIO_FEATURES)


def observation_columns(ds: Dataset | int) -> tuple[str, ...]:
    """The normaliser's columns for a twin (or a count of transmitters): :data:`PAPER_COLUMNS`, then the radio
    features of transmitters 1..K-1 (:func:`radio_columns`); a one-transmitter twin's are :data:`PAPER_COLUMNS`."""
    k = ds if isinstance(ds, (int, np.integer)) else ds.transmitters
    return PAPER_COLUMNS + tuple(c for j in range(1, int(k)) for c in radio_columns(j))


def tx_names(k: int) -> tuple[str, ...]:
    """The cell-part columns transmitter ``k >= 1`` adds: its 8 radio features and its has-path flag."""
    return radio_columns(k) + (tx_column(HAS_PATH, k),)


def preset_cell_columns(preset: str) -> int:
    """The cell-part columns of ``preset`` before any further transmitter's (10, or 46 with ``neighbors``)."""
    return len(PAPER_COLUMNS) + (4 * (len(RADIO_FEATURES) + 1) if check_preset(preset) == "neighbors" else 0)


def own_radio_columns(preset: str, transmitters: int = 1) -> list[int]:
    """Observation columns of the robot cell's radio features of every transmitter, transmitter 0's first: the
    fingerprint a planner or table policy localises by (``[2, ..., 9]`` with one transmitter)."""
    base, width = preset_cell_columns(preset), len(RADIO_FEATURES) + 1
    out = list(range(2, len(PAPER_COLUMNS)))
    for k in range(1, transmitters):
        out += range(base + (k - 1) * width, base + (k - 1) * width + len(RADIO_FEATURES))
    return out


def obs_dim(preset: str, transmitters: int = 1, sense_radius: int = 1, clock: str = "none") -> int:
    """The observation's width (module docstring): :data:`OBS_DIMS` plus 9 per further transmitter plus the ring plus
    the clock's columns."""
    ring = 2 * len(ring_offsets(check_sense_radius(sense_radius, preset)))
    extra = (len(RADIO_FEATURES) + 1) * (transmitters - 1) + ring + clock_columns(clock)
    return OBS_DIMS[check_preset(preset)] + extra


def check_transmitters(normalizer: Normalizer, ds: Dataset) -> int:
    """``K``, the transmitters of ``ds``, or :class:`InvalidSettingError` when the normaliser (a model's) was fitted
    on a twin with another count: its network takes the features of as many transmitters as it was trained with."""
    have, want = ds.transmitters, normalizer.transmitters
    if have != want:
        raise InvalidSettingError(
            f"the model (its feature normaliser) observes {want} transmitter(s), {ds.name} has {have}",
            hint=f"train a model on a twin with {have} transmitter(s) for this one, or use it on a twin with {want}",
        )
    return have


def check_preset(name: str) -> str:
    if name not in OBS_PRESETS:
        raise unknown_name("observation preset", name, OBS_PRESETS)
    return name


def check_sense_radius(radius, preset: str) -> int:
    """``radius`` as the sensing radius of ``preset``, or :class:`InvalidSettingError`: a whole number >= 1, and
    above 1 only with ``neighbors`` (the other presets sense no neighbour at all)."""
    if isinstance(radius, (bool, np.bool_)) or not isinstance(radius, (int, np.integer)) or radius < 1:
        raise InvalidSettingError(
            f"sense radius must be an integer >= 1, got {radius!r}", hint="1 = the four neighbours only"
        )
    if radius > 1 and preset != "neighbors":
        raise InvalidSettingError(
            f"a sense radius above 1 widens the 'neighbors' observation, got preset {preset!r}",
            hint="use obs='neighbors', or sense radius 1",
        )
    return int(radius)


def ring_offsets(radius: int) -> np.ndarray:
    """``int64[K, 2]``: the ``(dx, dy)`` of the cells at Manhattan distance 2..``radius`` (``K = 2R(R+1) - 4``), by
    distance, then ``dy``, then ``dx``: the order of the wider sensing columns."""
    out = []
    for d in range(2, radius + 1):
        for dy in range(-d, d + 1):
            rest = d - abs(dy)
            out += [(-rest, dy), (rest, dy)] if rest else [(0, dy)]
    return np.array(out, np.int64).reshape(-1, 2)


def ring_cells(nx: int, ny: int, radius: int) -> np.ndarray:
    """``int64[cells, K]``: the cell at each of :func:`ring_offsets` around every cell, -1 off the grid."""
    iy, ix = np.divmod(np.arange(nx * ny), nx)
    off = ring_offsets(radius)
    jx, jy = ix[:, None] + off[None, :, 0], iy[:, None] + off[None, :, 1]
    inside = (jx >= 0) & (jx < nx) & (jy >= 0) & (jy < ny)
    return np.where(inside, jy * nx + jx, -1)


@dataclass(frozen=True)
class Normalizer:
    """Per-column z-scoring: ``(value - mean) / std``. Fitted on a training dataset, stored with the model."""

    columns: tuple[str, ...]
    mean: tuple[float, ...]
    std: tuple[float, ...]

    @classmethod
    def fit(cls, ds: Dataset, columns: tuple[str, ...] | None = None) -> Normalizer:
        """Statistics of ``ds`` (of a moving twin: over the free cells of every snapshot); ``columns`` default to
        :func:`observation_columns` (every transmitter's features)."""
        columns = observation_columns(ds) if columns is None else columns
        if ds.is_moving:
            snaps = [ds.snapshot(k) for k in range(ds.snapshots)]
            values = np.concatenate([s.grid(list(columns)).reshape(-1, len(columns)) for s in snaps])
            free = np.concatenate([~np.asarray(s.blocked, bool).ravel() for s in snaps])
        else:
            values = ds.grid(list(columns))  # [H, W, F], NaN where null
            free = ~np.asarray(ds.blocked, bool)
        means, stds = [], []
        for k in range(len(columns)):
            v = values[..., k][free]
            v = v[np.isfinite(v)].astype(np.float64)
            m = float(v.mean()) if v.size else 0.0
            s = float(v.std()) if v.size else 1.0
            means.append(m)
            stds.append(s if s > 1e-12 * max(1.0, abs(m)) and s > 0 else 1.0)
        return cls(tuple(columns), tuple(means), tuple(stds))

    @property
    def transmitters(self) -> int:
        """The transmitters whose features it normalises (1 + those with :func:`radio_columns` among its columns)."""
        k = 1
        while radio_columns(k)[0] in self.columns:
            k += 1
        return k

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Normalise ``[..., F]`` values in ``self.columns`` order; NaN becomes 0."""
        out = (values - np.asarray(self.mean, np.float64)) / np.asarray(self.std, np.float64)
        return np.nan_to_num(out, nan=0.0).astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        return {"columns": list(self.columns), "mean": list(self.mean), "std": list(self.std)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Normalizer:
        return cls(tuple(d["columns"]), tuple(float(x) for x in d["mean"]), tuple(float(x) for x in d["std"]))


@dataclass(frozen=True)
class ObservationTable:
    """Lookup tables of one preset on one dataset: ``obs(cell, target) = [cell_part[cell], target_part[target]]``.

    On a moving twin of ``T`` snapshots the cell part has one block of rows per snapshot: the row of ``cell`` at
    snapshot ``t`` is ``t * H*W + cell`` (:meth:`row`), so a static twin is the case ``T = 1``."""

    preset: str
    cell_part: np.ndarray  # float32[T*H*W, Dc]
    target_part: np.ndarray  # float32[H*W, Dt]
    names: tuple[str, ...]
    #: ``bool[T*H*W]``: the cell is free and has radio features from at least one transmitter (the neighbours'
    #: has-radio flags read this)
    has_radio: np.ndarray | None = None
    #: the normaliser the tables were built with (measurement noise perturbs the raw values behind them)
    normalizer: Normalizer | None = None
    #: snapshots of a moving twin (1: static)
    snapshots: int = 1
    #: cells sensed around the robot: 1 = the four neighbours; R > 1 appends the wider ring's flags (module docstring)
    sense_radius: int = 1
    #: ``bool[T*H*W, K]``: the cell is free and transmitter ``k`` has a path to it (measurement noise perturbs only
    #: a transmitter's features that exist); None: column 0 is :attr:`has_radio` (one transmitter)
    heard_by: np.ndarray | None = None
    #: the clock's columns at the cell part's end (:mod:`dtradar_rl.task.clock`; "none": no columns)
    clock: str = "none"

    @property
    def transmitters(self) -> int:
        return 1 if self.heard_by is None else int(self.heard_by.shape[1])

    @property
    def radio_columns(self) -> list[int]:
        """The columns of the robot cell's radio features of every transmitter (:func:`own_radio_columns`)."""
        return own_radio_columns(self.preset, self.transmitters)

    @property
    def ring_columns(self) -> slice:
        """The cell-part columns of the wider ring's flags (now, then the snapshot before); empty at radius 1."""
        k = 2 * len(ring_offsets(self.sense_radius))
        dc = self.cell_part.shape[1] - clock_columns(self.clock)  # the clock's columns come after the ring's
        return slice(dc - k, dc)

    @property
    def dim(self) -> int:
        return self.cell_part.shape[1] + self.target_part.shape[1]

    def row(self, cell, t=0):
        """The cell-part row of ``cell`` at snapshot ``t``."""
        return t * self.target_part.shape[0] + cell

    def observe(self, cell, target, t=None) -> np.ndarray:
        """The observation on ``cell`` (at snapshot ``t`` of a moving twin) with ``target``."""
        rows = cell if t is None else self.row(cell, t)
        return np.concatenate([self.cell_part[rows], self.target_part[target]], axis=-1)


def build_observations(
    ds: Dataset, preset: str, normalizer: Normalizer, sense_radius: int = 1, clock: str = "none"
) -> ObservationTable:
    """The lookup tables of ``preset`` on ``ds``, normalised with ``normalizer`` (fitted on the training twin), with
    the flags of the cells up to ``sense_radius`` away (``neighbors``; module docstring) and the ``clock``'s phase
    columns last (:mod:`dtradar_rl.task.clock`; ``"none"``: none).

    On a moving twin: the tables of every snapshot stacked (each cell and its neighbours as they are in that
    snapshot); the target part is the static one (a target's position does not change when a mover covers it)."""
    check_preset(preset)
    radius = check_sense_radius(sense_radius, preset)
    check_transmitters(normalizer, ds)
    table = _build_moving(ds, preset, normalizer) if ds.is_moving else _build_static(ds, preset, normalizer)
    return with_clock(table if radius == 1 else _with_ring(table, ds.shape, radius), clock)


def _with_ring(table: ObservationTable, shape: tuple[int, int], radius: int) -> ObservationTable:
    """``table`` with the wider ring's flags appended to its cell part, now and in the snapshot before."""
    h, w = shape
    n, snaps = h * w, table.snapshots
    ring = ring_cells(w, h, radius)
    has_radio = table.has_radio.reshape(snaps, n)
    now = np.where(ring >= 0, has_radio[:, ring.clip(min=0)], False).astype(np.float32)  # [T, cells, K]
    before = np.roll(now, 1, axis=0)  # row t holds snapshot t - 1 (mod T); a static twin's is itself
    k = ring.shape[1]
    cell_part = np.concatenate([table.cell_part, now.reshape(snaps * n, k), before.reshape(snaps * n, k)], 1)
    dc = table.cell_part.shape[1]
    labels = [f"[{dx:+d},{dy:+d}]" for dx, dy in ring_offsets(radius)]
    names = (
        table.names[:dc]
        + tuple(f"has_radio{c}" for c in labels)
        + tuple(f"has_radio_before{c}" for c in labels)
        + table.names[dc:]
    )
    return replace(table, cell_part=np.ascontiguousarray(cell_part, np.float32), names=names, sense_radius=radius)


def _build_static(ds: Dataset, preset: str, normalizer: Normalizer) -> ObservationTable:
    h, w = ds.shape
    n = h * w
    raw = ds.grid(list(normalizer.columns)).reshape(n, -1).astype(np.float64)
    blocked = np.asarray(ds.blocked, bool).ravel()
    raw[blocked] = np.nan
    z = normalizer.apply(raw)  # [n, F], 0 where missing
    col = {c: k for k, c in enumerate(normalizer.columns)}
    paper = z[:, [col[c] for c in PAPER_COLUMNS]]
    names = list(PAPER_COLUMNS)
    target = np.zeros((n, 0), np.float32)
    tnames: list[str] = []
    if preset in ("goal", "neighbors"):
        target = paper[:, :2].copy()
        tnames = ["target_x_m", "target_y_m"]
    parts = [paper]
    # per transmitter: free with all its radio features; the has-radio flag is any of them (module docstring)
    heard = np.stack(
        [
            ~blocked & np.isfinite(raw[:, [col[c] for c in radio_columns(k)]]).all(1)
            for k in range(normalizer.transmitters)
        ],
        1,
    )
    has_radio = heard.any(1).astype(np.float32)
    if preset == "neighbors":
        radio = paper[:, 2:]
        iy, ix = np.divmod(np.arange(n), w)
        for (dx, dy), act in zip(ACTION_DELTAS, ("X-", "X+", "Y-", "Y+")):
            jx, jy = ix + dx, iy + dy
            inside = (jx >= 0) & (jx < w) & (jy >= 0) & (jy < h)
            j = np.where(inside, jy * w + jx, 0)
            flag = np.where(inside, has_radio[j], 0.0).astype(np.float32)
            parts += [radio[j] * flag[:, None], flag[:, None]]
            names += [f"{act}:{c}" for c in RADIO_FEATURES] + [f"{act}:has_radio"]
    for k in range(1, heard.shape[1]):  # the robot cell's features of each further transmitter, and its flag
        parts += [z[:, [col[c] for c in radio_columns(k)]], heard[:, k, None].astype(np.float32)]
        names += tx_names(k)
    cell_part = np.ascontiguousarray(np.concatenate(parts, 1), np.float32)
    return ObservationTable(
        preset,
        cell_part,
        np.ascontiguousarray(target),
        tuple(names + tnames),
        has_radio > 0.5,
        normalizer,
        heard_by=heard if heard.shape[1] > 1 else None,
    )


def _build_moving(ds: Dataset, preset: str, normalizer: Normalizer) -> ObservationTable:
    snaps = [_build_static(ds.snapshot(k), preset, normalizer) for k in range(ds.snapshots)]
    n = snaps[0].target_part.shape[0]
    has_radio = np.concatenate([s.has_radio for s in snaps])
    heard_by = None if snaps[0].heard_by is None else np.concatenate([s.heard_by for s in snaps])
    # a target's part from a snapshot where its cell is free (a blocked cell's part is blanked)
    free = np.stack([~np.asarray(ds.snapshot(k).blocked, bool).ravel() for k in range(ds.snapshots)])
    first_free = free.argmax(0)
    target = np.stack([s.target_part for s in snaps])[first_free, np.arange(n)]
    return ObservationTable(
        preset,
        np.ascontiguousarray(np.concatenate([s.cell_part for s in snaps]), np.float32),
        np.ascontiguousarray(target, np.float32),
        snaps[0].names,
        has_radio,
        normalizer,
        snapshots=len(snaps),
        heard_by=heard_by,
    )
