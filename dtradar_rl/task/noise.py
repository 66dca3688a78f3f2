"""Measurement noise: what a real receiver would read instead of the ray tracer's exact radio features.

Every figure of an agent trained and evaluated on the tables assumes the robot measures the ray tracer's values to
the float32 digit. A receiver estimates them: angles from a small antenna array, delay from a band-limited
channel, gain from a quantised and fluctuating power reading. A :class:`NoiseModel` says how far off each estimate
is (zero-mean Gaussian errors, independent per feature, per observed cell and per step), by level
(:data:`NOISE_LEVELS`): ``none``, ``realistic`` and ``2x`` (every standard deviation doubled).

``realistic`` (the values and where they come from are in the docs, Navigation → Measurement noise):

============================  =========  ==========================================================================
feature                       error (1σ)
============================  =========  ==========================================================================
AoA azimuth, AoA zenith       5°         angle estimation with a few-element array at 2.4 GHz (MUSIC/ESPRIT-class
AoD azimuth, AoD zenith       5°         estimators on commodity Wi-Fi: median errors of a few degrees)
delay ``tau_s``               5 ns       super-resolution ToF on a 20-40 MHz channel (Wi-Fi fine timing: ~1-2 m)
gain ``|a|``                  3 dB       received-power fluctuation and quantisation of commodity receivers
phase ``phase_rad`` and ``a``  10°        a phase-calibrated receiver (an uncalibrated one's phase is random)
============================  =========  ==========================================================================

A gain error scales the complex coefficient ``a`` (``a_re``, ``a_im``) by ``10^(e/20)``; a phase error rotates it
and shifts ``phase_rad``, so the four features stay consistent. The robot's own position (``x``, ``y``) and the
target's are not perturbed, and neither are the has-radio flags: a receiver knows whether it hears the transmitter.

:class:`RadioNoise` applies a model to the observations of one :class:`~dtradar_rl.task.observations.ObservationTable`
(the robot's own cell and, with the ``neighbors`` preset, its four neighbours): both environments draw one set of
errors per robot at every reset and step, from their own seeded generator (never the one that samples pairs, so
``none`` changes nothing), and apply it whenever they observe. On a twin with several transmitters each further
transmitter's features of the robot's cell are one more group of errors, drawn and applied as transmitter 0's (a
receiver estimates each transmitter's path on its own), and only where that transmitter has a path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from dtradar_data.core.errors import unknown_name
from dtradar_rl.task.observations import RADIO_FEATURES, Normalizer, ObservationTable, radio_columns

#: Offset of a noise generator's seed from its env's seed (a separate stream from pair sampling).
NOISE_SEED_OFFSET = 7919

#: The per-feature errors drawn for each observed cell: AoA az, AoA zen, AoD az, AoD zen, delay, gain, phase.
ERRORS = ("aoa_az", "aoa_zen", "aod_az", "aod_zen", "tau", "gain", "phase")


@dataclass(frozen=True)
class NoiseModel:
    """Standard deviations of a receiver's estimation errors."""

    level: str = "none"
    angle_deg: float = 0.0
    delay_ns: float = 0.0
    gain_db: float = 0.0
    phase_deg: float = 0.0

    @property
    def is_zero(self) -> bool:
        return not (self.angle_deg or self.delay_ns or self.gain_db or self.phase_deg)

    def sigmas(self) -> np.ndarray:
        """``float64[7]``: the standard deviation of each of :data:`ERRORS` in SI units (rad, s, dB, rad)."""
        a = math.radians(self.angle_deg)
        return np.array([a, a, a, a, self.delay_ns * 1e-9, self.gain_db, math.radians(self.phase_deg)])

    def scaled(self, factor: float, level: str) -> NoiseModel:
        return NoiseModel(
            level, self.angle_deg * factor, self.delay_ns * factor, self.gain_db * factor, self.phase_deg * factor
        )


REALISTIC = NoiseModel("realistic", angle_deg=5.0, delay_ns=5.0, gain_db=3.0, phase_deg=10.0)
NOISE_LEVELS: dict[str, NoiseModel] = {"none": NoiseModel(), "realistic": REALISTIC, "2x": REALISTIC.scaled(2, "2x")}


def noise_model(level: str | NoiseModel | None) -> NoiseModel:
    """The model of a level name (``none``, ``realistic``, ``2x``), or :class:`UnknownNameError` with a suggestion."""
    if isinstance(level, NoiseModel):
        return level
    level = level or "none"
    if level not in NOISE_LEVELS:
        raise unknown_name("noise level", level, NOISE_LEVELS)
    return NOISE_LEVELS[level]


class RadioNoise:
    """Draws and applies a :class:`NoiseModel`'s errors to observations of one table (see the module docstring)."""

    def __init__(self, model: NoiseModel, table: ObservationTable, normalizer: Normalizer, device: torch.device):
        self.model, self.device = model, torch.device(device)
        names = table.names
        col = {c: k for k, c in enumerate(normalizer.columns)}
        dev = self.device
        # The observed cells: the robot's own (its radio columns) and each neighbour's (prefixed, with a flag), then
        # the robot's own for each further transmitter (its tx{k}_ columns; group 0's presence is transmitter 0's).
        groups, flags, tx = [[names.index(c) for c in RADIO_FEATURES]], [-1], [0]
        for act in [n.split(":")[0] for n in names if n.endswith(":has_radio")]:
            groups.append([names.index(f"{act}:{c}") for c in RADIO_FEATURES])
            flags.append(names.index(f"{act}:has_radio"))
            tx.append(0)
        for k in range(1, table.transmitters):
            groups.append([names.index(c) for c in radio_columns(k)])
            flags.append(-1)
            tx.append(k)
        # the statistics of each group's columns, [G, 8] (a neighbour's are transmitter 0's)
        stats = [[col[c] for c in radio_columns(k)] for k in tx]
        self.mean = torch.as_tensor(np.asarray(normalizer.mean)[stats], dtype=torch.float64, device=dev)
        self.std = torch.as_tensor(np.asarray(normalizer.std)[stats], dtype=torch.float64, device=dev)
        self.sigma = torch.as_tensor(model.sigmas(), dtype=torch.float64, device=dev)
        self.columns = torch.as_tensor(groups, dtype=torch.long, device=dev)  # [G, 8]
        self.flag_columns = flags
        #: the own-cell groups (flag -1) and their transmitters: they read :attr:`heard`, the neighbours their flag
        self._own = [g for g, f in enumerate(flags) if f < 0]
        heard = table.has_radio[:, None] if table.heard_by is None else table.heard_by
        #: ``bool[cells, K]``: the cell has transmitter k's radio features (the own-cell groups' presence)
        self.heard = torch.as_tensor(heard[:, [tx[g] for g in self._own]], dtype=torch.bool, device=dev)
        self.k = {c: i for i, c in enumerate(RADIO_FEATURES)}

    @property
    def groups(self) -> int:
        return int(self.columns.shape[0])

    def draw(self, n: int, gen: torch.Generator) -> torch.Tensor:
        """``float64[n, groups, 7]`` standard-normal errors (scaled when applied), from ``gen``."""
        return torch.randn((n, self.groups, len(ERRORS)), generator=gen, dtype=torch.float64, device=self.device)

    def apply(self, obs: torch.Tensor, cells: torch.Tensor, errors: torch.Tensor) -> torch.Tensor:
        """``obs`` (``float32[n, D]``, z-scored) with ``errors`` (from :meth:`draw`) applied to every observed cell
        that has radio features."""
        if self.model.is_zero:
            return obs
        out = obs.clone()
        z = obs[:, self.columns].to(torch.float64)  # [n, G, 8]
        raw = z * self.std + self.mean
        e = errors * self.sigma  # [n, G, 7]
        k = self.k
        for i, name in enumerate(("aoa_az_rad", "aoa_zen_rad", "aod_az_rad", "aod_zen_rad")):
            raw[..., k[name]] += e[..., i]
        raw[..., k["tau_s"]] += e[..., 4]
        gain = torch.pow(10.0, e[..., 5] / 20.0)
        c, s = torch.cos(e[..., 6]), torch.sin(e[..., 6])
        re, im = raw[..., k["a_re"]], raw[..., k["a_im"]]
        raw[..., k["a_re"]], raw[..., k["a_im"]] = gain * (re * c - im * s), gain * (re * s + im * c)
        raw[..., k["phase_rad"]] = (
            torch.remainder(raw[..., k["phase_rad"]] + e[..., 6] + math.pi, 2 * math.pi) - math.pi
        )
        own = self.heard[cells]  # [n, own groups]
        present = torch.stack(
            [own[:, self._own.index(g)] if f < 0 else obs[:, f] > 0.5 for g, f in enumerate(self.flag_columns)], dim=1
        )  # [n, G]
        noisy = ((raw - self.mean) / self.std).to(obs.dtype)
        z_new = torch.where(present[..., None], noisy, z.to(obs.dtype))
        out[:, self.columns.reshape(-1)] = z_new.reshape(len(obs), -1)
        return out


__all__ = ["ERRORS", "NOISE_LEVELS", "NOISE_SEED_OFFSET", "REALISTIC", "NoiseModel", "RadioNoise", "noise_model"]
