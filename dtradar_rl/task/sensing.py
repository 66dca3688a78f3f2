"""What a robot senses: the named sensing settings and the honest readings a robot with a radio receiver takes.

A robot with a radio receiver knows what its own receiver measures on the cell it stands on, its own moves and whether
each one moved it, optionally which of its four neighbouring cells are blocked (a proximity sensor: a ring of
range-finders or bumpers, non-imaging, on or off), the blueprint twin as its map, and where its target is on that map.
It is **not** told where it starts, where it is at any step, or what the radio of any other cell is. A
:class:`Sensing` names one such setting; :data:`SENSINGS` holds the named ones:

==============================  ===================================================================================
sensing                         what the robot observes
==============================  ===================================================================================
``radio`` (the default)         its own cell's measurement of every transmitter (angles, delay, gain, phase) under the
                                receiver's noise, proximity, odometry and bumps, the target on the map
``radio-no-proximity``          the same without the proximity sensor (odometry and bumps only)
``no-angles`` ... ``no-phase``  ``radio`` without one group of radio features (:data:`GROUPS`)
``rssi``                        the gain only (a received-power reading), proximity, odometry
``no-radio``                    proximity, odometry and bumps only: no radio at all, not even whether a
                                transmitter is heard (what the map's layout alone localises)
``privileged``                  **privileged** (an upper bound): the observation presets of the learnt agents, which
                                hold the robot's exact ``x, y`` and, with ``neighbors``, the radio of the four
                                neighbouring cells read from the twin being navigated
==============================  ===================================================================================

:class:`Readings` builds the honest observations of a twin as lookup tables, from the robot's **own** cell only: the
radio part of a row is that cell's own features (no ``x_m``/``y_m`` column is read), and the proximity part is whether
each move from that cell is blocked. The environment (:class:`~dtradar_rl.envs.honest.HonestNavEnv`) adds the
receiver's noise, the odometry and the target's map coordinates. An honest observation, in order:

* per transmitter ``k`` (:data:`MEASURED`, 8 columns): the measured AoA azimuth and zenith, AoD azimuth and zenith
  (rad), delay (s), gain of the strongest path ``20 log10 |a|`` (dB) and its phase (rad), then ``heard`` (1: the
  receiver hears transmitter ``k`` on this cell). A feature group the sensing leaves out, and every feature of a
  transmitter not heard, reads 0;
* ``blocked[X-]``, ``blocked[X+]``, ``blocked[Y-]``, ``blocked[Y+]``: the proximity sensor (0 when it is off);
* ``moved``: the last move moved the robot (0 after a bump, a wait and at the first step);
* ``last[X-]`` ... ``last[Y+]``: the last move, one-hot (all 0 at the first step);
* ``switched_on``: 1 at the episode's first observation (the robot is switched on somewhere on the map);
* ``target_x_m``, ``target_y_m``: the target on the map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_data.core.schema import tx_column
from dtradar_rl.task.grid_mdp import ACTION_DELTAS

#: The measured quantities per transmitter, in order: what the noise model's errors (``task.noise.ERRORS``) perturb.
MEASURED: tuple[str, ...] = ("aoa_az_rad", "aoa_zen_rad", "aod_az_rad", "aod_zen_rad", "tau_s", "gain_db", "phase_rad")
#: Which measured quantities are angles on a circle (an error wraps around): the azimuths and the phase.
CIRCULAR = np.array([True, False, True, False, False, False, True])
#: Feature groups a sensing can leave out, by index into :data:`MEASURED`.
GROUPS: dict[str, tuple[int, ...]] = {"angles": (0, 1, 2, 3), "delay": (4,), "gain": (5,), "phase": (6,)}
#: Columns per transmitter: the measured quantities and the ``heard`` flag.
PER_TX = len(MEASURED) + 1
#: Columns after the transmitters': proximity (4), moved, last move (4), switched on, target x, y.
TAIL = 4 + 1 + 4 + 1 + 2
ACTIONS = ("X-", "X+", "Y-", "Y+")


@dataclass(frozen=True)
class Sensing:
    """One named sensing setting: which radio groups the robot measures, whether it has the proximity sensor, and
    whether it is the privileged setting (the learnt agents' observation presets, position included)."""

    name: str
    groups: tuple[str, ...] = tuple(GROUPS)
    proximity: bool = True
    privileged: bool = False

    @property
    def honest(self) -> bool:
        return not self.privileged

    @property
    def measured(self) -> np.ndarray:
        """``bool[7]``: the quantities of :data:`MEASURED` this sensing measures."""
        out = np.zeros(len(MEASURED), bool)
        for g in self.groups:
            out[list(GROUPS[g])] = True
        return out

    def describe(self) -> str:
        """One line on what the robot observes (shown in tables and cards)."""
        if self.privileged:
            return "privileged: its exact x, y and the radio of the neighbouring cells of the navigated twin"
        radio = "no radio" if not self.groups else "own-cell radio (" + ", ".join(self.groups) + ")"
        return radio + (", proximity" if self.proximity else "") + ", odometry and bumps; not told its position"


_ALL = tuple(GROUPS)
SENSINGS: dict[str, Sensing] = {
    s.name: s
    for s in (
        Sensing("radio"),
        Sensing("radio-no-proximity", proximity=False),
        *(Sensing(f"no-{g}", tuple(x for x in _ALL if x != g)) for g in _ALL),
        Sensing("rssi", ("gain",)),
        Sensing("no-radio", ()),
        Sensing("privileged", privileged=True),
    )
}
DEFAULT_SENSING = "radio"
#: The observation "preset" name of honest observations wherever a preset is recorded (a logged dataset's
#: ``observations.preset``, an agent's ``obs_preset``): not one of the privileged presets.
HONEST_PRESET = "honest"


def sensing_for(name: str | Sensing) -> Sensing:
    """The named :class:`Sensing` (an instance passes through), or a "did you mean" error."""
    if isinstance(name, Sensing):
        return name
    if name not in SENSINGS:
        raise unknown_name("sensing", name, tuple(SENSINGS))
    return SENSINGS[name]


def honest_dim(transmitters: int) -> int:
    """The width of an honest observation on a twin with ``transmitters`` transmitters."""
    return PER_TX * transmitters + TAIL


def honest_names(transmitters: int) -> tuple[str, ...]:
    """The honest observation's column names (module docstring)."""
    names = [tx_column(c, k) for k in range(transmitters) for c in (*MEASURED, "heard")]
    names += [f"blocked[{a}]" for a in ACTIONS] + ["moved"] + [f"last[{a}]" for a in ACTIONS]
    return tuple(names + ["switched_on", "target_x_m", "target_y_m"])


def measured_features(ds: Dataset, k: int) -> np.ndarray:
    """``float64[H*W, 7]``: transmitter ``k``'s :data:`MEASURED` quantities on every cell of a static twin (or one
    snapshot), NaN where the cell is blocked or the transmitter has no path to it. Reads only radio columns."""
    cols = [tx_column(c, k) for c in ("aoa_az_rad", "aoa_zen_rad", "aod_az_rad", "aod_zen_rad", "tau_s")]
    g = ds.grid(cols + [tx_column("a_re", k), tx_column("a_im", k), tx_column("phase_rad", k)]).astype(np.float64)
    g = g.reshape(-1, g.shape[-1])
    power = g[:, 5] ** 2 + g[:, 6] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(power > 0, 10 * np.log10(power), np.nan)
    out = np.concatenate([g[:, :5], gain[:, None], g[:, 7:8]], 1)
    out[np.asarray(ds.blocked, bool).ravel()] = np.nan
    out[~np.isfinite(out).all(1)] = np.nan
    return out


def neighbours(shape: tuple[int, int]) -> np.ndarray:
    """``int64[H*W, 4]``: the cell each move leads to on an empty grid, -1 off the grid."""
    h, w = shape
    iy, ix = np.divmod(np.arange(h * w), w)
    jx, jy = ix[:, None] + ACTION_DELTAS[None, :, 0], iy[:, None] + ACTION_DELTAS[None, :, 1]
    inside = (jx >= 0) & (jx < w) & (jy >= 0) & (jy < h)
    return np.where(inside, jy * w + jx, -1)


@dataclass(frozen=True)
class Readings:
    """The honest readings of a twin, one row per cell (per snapshot of a moving twin: row ``t * H*W + cell``), each
    built from that cell alone: ``radio float32[rows, K, 7]`` (0 where not heard), ``heard bool[rows, K]`` and
    ``blocked_around bool[rows, 4]`` (a move from the cell is blocked then: an obstacle, a mover or the grid's edge);
    ``target_xy float32[H*W, 2]`` the map coordinates of every cell as a target."""

    radio: np.ndarray
    heard: np.ndarray
    blocked_around: np.ndarray
    target_xy: np.ndarray

    @property
    def transmitters(self) -> int:
        return int(self.heard.shape[1])

    @classmethod
    def from_dataset(cls, ds: Dataset) -> Readings:
        snaps = [ds.snapshot(t) for t in range(ds.snapshots)]
        nbr = neighbours(ds.shape)
        radio, heard, around = [], [], []
        for s in snaps:
            feats = np.stack([measured_features(s, k) for k in range(ds.transmitters)], 1)  # [cells, K, 7]
            ok = np.isfinite(feats).all(2)
            radio.append(np.where(ok[..., None], feats, 0.0))
            heard.append(ok)
            blocked = np.asarray(s.blocked, bool).ravel()
            around.append((nbr < 0) | blocked[nbr.clip(min=0)])
        xy = snaps[0].grid(["x_m", "y_m"]).reshape(-1, 2)  # a target's place on the map (the grid is the map's)
        return cls(
            np.concatenate(radio).astype(np.float32),
            np.concatenate(heard),
            np.concatenate(around),
            np.ascontiguousarray(xy, np.float32),
        )
