"""Channels of any array pair from a stored dataset: DeepMIMO's workflow (trace once, generate the channels of a study)
on dtradar's per-path table.

For each path the stored transfer matrix ``T`` (isotropic V/H ports, global θ̂/φ̂ basis, baseband) and the element
patterns ``c`` (transmit) and ``d`` (receive) in that basis (:class:`~.arrays.Array`) give the path's coefficient
at one port pair, ``a = d^H T c``; the plane-wave model adds each element's phase ``2π/λ · r·k`` along the
departure (arrival) direction ``k``, as Sionna's synthetic arrays do (``Paths._apply_synthetic_array``). The impulse
response is these taps with the delays; the frequency response at baseband frequencies ``f`` (subcarriers around the
carrier) is ``H(f) = Σ_paths a · exp(-j2π f τ)``, Sionna's ``Paths.cfr``. With ``normalize_delays`` (Sionna's
default) delays count from each cell's first path, and the baseband phase too, as in ``Paths.cir``.

The carrier is the dataset's: the materials' parameters and the stored coefficients are those of the traced
frequency, so another carrier needs another trace (``--rt.frequency-hz``); subcarriers may span any band around it
that the plane-wave, frequency-flat-material model covers.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from dtradar_data.channels.arrays import Array, _unit, look_at_orientation
from dtradar_data.channels.stored import StoredPaths
from dtradar_data.core.errors import InvalidSettingError

SPEED_OF_LIGHT = 299_792_458.0


def ofdm_frequencies(num_subcarriers: int, spacing_hz: float) -> np.ndarray:
    """Baseband subcarrier frequencies, Sionna's ``subcarrier_frequencies``: ``(-N/2 .. N/2-1)·Δf`` for even ``N``,
    ``(-(N-1)/2 .. (N-1)/2)·Δf`` for odd."""
    n = int(num_subcarriers)
    if n < 1 or not spacing_hz > 0:
        raise InvalidSettingError(
            f"an OFDM grid needs >= 1 subcarrier and a positive spacing, got {num_subcarriers}, {spacing_hz}",
            hint="e.g. ofdm_frequencies(64, 30e3)",
        )
    start = -(n // 2) if n % 2 == 0 else -((n - 1) // 2)
    return np.arange(start, start + n, dtype=np.float64) * float(spacing_hz)


@dataclass(frozen=True)
class Channels:
    """The channels of ``C`` cells. ``a``: ``complex64 [C, num_rx_ports, num_tx_ports, P]`` baseband taps (zero
    past a cell's ``num_paths``); ``tau_s``: ``float64 [C, P]`` their delays (-1 past ``num_paths``); ``h``:
    ``complex64 [C, num_rx_ports, num_tx_ports, F]`` the frequency response at ``frequencies_hz`` (baseband)."""

    ix: np.ndarray
    iy: np.ndarray
    num_paths: np.ndarray
    a: np.ndarray
    tau_s: np.ndarray
    frequencies_hz: np.ndarray
    h: np.ndarray


class ChannelGenerator:
    """Channels between ``tx`` and ``rx`` arrays for the cells of a dataset loaded with its per-path table
    (``dtradar_data.load(name, paths=True)``).

    ``tx_orientation`` / ``rx_orientation``: Sionna's (yaw, pitch, roll) in rad; the transmitter's default is the
    dataset's own (its orientation, else its look-at point), the receiver's (0, 0, 0). ``frequencies_hz``: baseband
    frequencies (e.g. :func:`ofdm_frequencies`); ``transmitter``: which one, for a twin with several.
    """

    def __init__(
        self,
        dataset,
        tx: Array,
        rx: Array,
        *,
        frequencies_hz=(0.0,),
        tx_orientation=None,
        rx_orientation=(0.0, 0.0, 0.0),
        carrier_hz: float | None = None,
        normalize_delays: bool = True,
        transmitter: int = 0,
    ):
        if dataset.paths_table is None:
            raise InvalidSettingError(
                f"{dataset.name} was loaded without its per-path table", hint="load it with paths=True"
            )
        self.dataset, self.tx, self.rx = dataset, tx, rx
        self.carrier_hz = float(dataset.meta["rt"]["frequency_hz"])
        if carrier_hz is not None and not math.isclose(carrier_hz, self.carrier_hz, rel_tol=1e-9):
            raise InvalidSettingError(
                f"{dataset.name} was traced at {self.carrier_hz:g} Hz, not {carrier_hz:g} Hz: its path coefficients "
                "(materials, antenna apertures) belong to that carrier",
                hint="pick subcarriers around the traced carrier, or build a version at the other frequency "
                "(--rt.frequency-hz)",
            )
        self.wavelength_m = SPEED_OF_LIGHT / self.carrier_hz
        self.frequencies_hz = np.atleast_1d(np.asarray(frequencies_hz, np.float64))
        self.transmitter = transmitter
        self.tx_orientation = tuple(tx_orientation) if tx_orientation is not None else self._tx_pose(transmitter)
        self.rx_orientation = tuple(rx_orientation)
        self.normalize_delays = normalize_delays
        self._tx_pos = tx.element_positions(self.wavelength_m, self.tx_orientation)
        self._rx_pos = rx.element_positions(self.wavelength_m, self.rx_orientation)

    def _tx_pose(self, k: int) -> tuple[float, float, float]:
        meta = self.dataset.meta
        t = (meta.get("transmitters") or [meta["transmitter"]])[k]
        if t.get("orientation_deg") is not None:
            return tuple(math.radians(v) for v in t["orientation_deg"])
        if t.get("look_at_m") is not None:
            return look_at_orientation(t["position_m"], t["look_at_m"])
        return (0.0, 0.0, 0.0)

    def free_cells(self) -> np.ndarray:
        """``int [C, 2]`` ``(ix, iy)`` of every free cell, row-major: the default selection."""
        t = self.dataset.table
        free = ~t.column("blocked").to_numpy(zero_copy_only=False)
        return np.stack([t.column("ix").to_numpy()[free], t.column("iy").to_numpy()[free]], axis=1)

    def generate(self, cells=None) -> Channels:
        """The channels of ``cells`` (``(ix, iy)`` pairs; default every free cell) in one batch."""
        return self._one(self._cells(cells))

    def batches(self, cells=None, batch_cells: int = 512) -> Iterator[Channels]:
        """:meth:`generate` in batches of ``batch_cells`` cells, so that a city quadrant's fit in memory."""
        cells = self._cells(cells)
        for start in range(0, len(cells), max(1, int(batch_cells))):
            yield self._one(cells[start : start + batch_cells])

    def _cells(self, cells) -> np.ndarray:
        if cells is None:
            return self.free_cells()
        cells = np.asarray(cells)
        if cells.dtype == bool:  # a [ny, nx] mask
            iy, ix = np.nonzero(cells)
            return np.stack([ix, iy], axis=1)
        return cells.astype(np.int64).reshape(-1, 2)

    def _one(self, cells: np.ndarray) -> Channels:
        sp = StoredPaths.from_table(self.dataset.paths_table, cells, name=self.dataset.name, tx=self.transmitter)
        a, tau = self._taps(sp)
        counts = sp.counts
        width = int(counts.max(initial=0))
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(len(sp.cell)) - starts[sp.cell]
        taps = np.zeros((sp.num_cells, width, a.shape[1] * a.shape[2]), np.complex128)
        taps[sp.cell, slot] = a.reshape(len(a), -1)
        delays = np.full((sp.num_cells, width), -1.0)
        delays[sp.cell, slot] = tau
        phase = np.exp(-2j * np.pi * delays[:, :, None] * self.frequencies_hz)  # padding taps are zero
        h = np.matmul(taps.transpose(0, 2, 1), phase)  # [C, ports, F]
        shape = (sp.num_cells, a.shape[1], a.shape[2])
        return Channels(
            ix=sp.ix,
            iy=sp.iy,
            num_paths=counts,
            a=taps.transpose(0, 2, 1).reshape(*shape, width).astype(np.complex64),
            tau_s=delays,
            frequencies_hz=self.frequencies_hz,
            h=h.reshape(*shape, len(self.frequencies_hz)).astype(np.complex64),
        )

    def _taps(self, sp: StoredPaths) -> tuple[np.ndarray, np.ndarray]:
        """``a`` ``[M, rx ports, tx ports]`` and the delays ``[M]`` of every stored path (normalised or not)."""
        c = self.tx.field(sp.theta_t, sp.phi_t, self.tx_orientation)  # [Pt, M, 2]
        d = self.rx.field(sp.theta_r, sp.phi_r, self.rx_orientation)  # [Pr, M, 2]
        per_pattern = np.einsum("rmi,mij,tmj->mrt", d.conj(), sp.transfer, c)  # [M, Pr, Pt]
        k = 2 * np.pi / self.wavelength_m
        ph_t = np.exp(1j * k * _unit(sp.theta_t, sp.phi_t) @ self._tx_pos.T)  # [M, Et]
        ph_r = np.exp(1j * k * _unit(sp.theta_r, sp.phi_r) @ self._rx_pos.T)  # [M, Er]
        a = per_pattern[:, :, None, :, None] * ph_r[:, None, :, None, None] * ph_t[:, None, None, None, :]
        a = a.reshape(len(a), self.rx.num_ports, self.tx.num_ports)  # ports: pattern first, then element
        tau = sp.tau_s
        if self.normalize_delays and len(tau):
            first = np.full(sp.num_cells, np.inf)
            np.minimum.at(first, sp.cell, tau)
            # the stored baseband phase is exp(-j2π f_c τ); Sionna's, with normalised delays, exp(-j2π f_c (τ - τ0))
            a = a * np.exp(2j * np.pi * self.carrier_hz * first[sp.cell])[:, None, None]
            tau = tau - first[sp.cell]
        return a, tau
