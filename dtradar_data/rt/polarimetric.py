"""Each path's 2 × 2 polarimetric transfer matrix, computed in the same PathSolver call as the dataset's own
coefficients (``--rt.path-channels``): what makes the channel of any array exact under the plane-wave model
(:mod:`dtradar_data.channels`).

Sionna transports one Jones vector per transmit antenna pattern along each path and projects the field that reaches
the receiver onto each receive pattern (``FieldCalculator``). :class:`PolarimetricFieldCalculator` transports two
more: the fields of unit-gain isotropic ports, vertical (θ̂) and horizontal (φ̂), in the **world** frame (orientation
(0, 0, 0), whatever the transmitter's), and projects them onto the same two receive ports. Because the transport and
the projection are linear, any array's coefficient then follows as ``a = d^H T c``, with ``c`` and ``d`` the
transmit and receive element patterns in the global spherical basis (θ̂, φ̂) of the path's departure and arrival
directions.

Why extra patterns in the same call rather than a second trace: the paths (and so the rows) are those of the
dataset's own trace, and the dataset's coefficients are computed by the same expressions as before, so the other
columns keep their bytes (checked in tests/data/channels/). The extra coefficients travel as one more row of the
buffer's ``a`` list, which ``PathsBuffer.discard_invalid`` gathers with the others and ``Paths`` never reads (it
reads ``a[n][m]`` for its own patterns only); :func:`transfer_matrices` puts them in ``Paths``' tensor layout.

Import it only after :func:`dtradar_data.rt.tracer._import_sionna` picked the Mitsuba variant (as the
batch-independent solver).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
from sionna.rt.path_solvers.field_calculator import FieldCalculator

__all__ = ["PolarimetricFieldCalculator", "install", "transfer_matrices", "vertices"]


def _iso_v(theta, phi):
    # exactly θ̂: Sionna's "iso" "VH" H port is cos(π/2)·θ̂ + φ̂ in float32, a -147 dB leak of V into H
    return mi.Complex2f(dr.ones(mi.Float, dr.width(theta)), 0.0), mi.Complex2f(dr.zeros(mi.Float, dr.width(theta)), 0.0)


def _iso_h(theta, phi):
    return mi.Complex2f(dr.zeros(mi.Float, dr.width(theta)), 0.0), mi.Complex2f(dr.ones(mi.Float, dr.width(theta)), 0.0)


_PORTS = [_iso_v, _iso_h]


class PolarimetricFieldCalculator(FieldCalculator):
    """Sionna's field calculator with two more transmit and two more receive ports (isotropic V, H in the world
    frame): their four coefficients are ``paths.a[-1]`` (V←V, V←H, H←V, H←H: receive port first), left out of the
    paths' validity so that which paths are kept does not change."""

    def evaluate_transmitter_antenna_patterns(
        self, paths, src_positions, tgt_positions, src_orientations, src_antenna_patterns
    ):
        own = super().evaluate_transmitter_antenna_patterns(
            paths, src_positions, tgt_positions, src_orientations, src_antenna_patterns
        )
        world = dr.zeros(mi.Point3f, dr.width(src_orientations))
        ports = super().evaluate_transmitter_antenna_patterns(paths, src_positions, tgt_positions, world, _PORTS)
        return own + ports

    def compute_channel_coefficients(
        self, e_fields, wavelength, ki_world, paths, tgt_orientations, tgt_antenna_patterns
    ):
        n = len(e_fields) - len(_PORTS)
        a, valid = super().compute_channel_coefficients(
            e_fields[:n], wavelength, ki_world, paths, tgt_orientations, tgt_antenna_patterns
        )
        world = dr.zeros(mi.Point3f, dr.width(tgt_orientations))
        t, _ = super().compute_channel_coefficients(e_fields[n:], wavelength, ki_world, paths, world, _PORTS)
        return [*a, [t[0][0], t[0][1], t[1][0], t[1][1]]], valid


def install(solver) -> None:
    """Make ``solver`` (a Sionna ``PathSolver``, or the batch-independent one) compute the transfer matrices."""
    calc = PolarimetricFieldCalculator()
    calc.loop_mode = solver._field_calculator.loop_mode
    solver._field_calculator = calc


def _scatter_index(paths) -> np.ndarray | None:
    """Each buffer entry's flat index in ``Paths``' ``[num_rx, num_tx, max_num_paths]`` tensors (synthetic arrays),
    as ``Paths._build_from_buffer`` computes it; None when no path was found."""
    if paths._paths_buffer.buffer_size == 0:
        return None
    rx = np.asarray(paths._rx_ind, np.int64)
    tx = np.asarray(paths._tx_ind, np.int64)
    p = np.asarray(paths._path_ind, np.int64)
    return (rx * paths._num_tx + tx) * int(paths._max_num_paths) + p


def transfer_matrices(paths) -> np.ndarray:
    """``complex64 [num_rx, num_tx, max_num_paths, 2, 2]``: each path's passband transfer matrix between unit-gain
    isotropic ports (rows: receive V, H; columns: transmit V, H), zero for padding, as ``Paths.a`` is (no carrier
    phase). Needs a solver with :func:`install` and synthetic arrays."""
    if not paths.synthetic_array:
        raise ValueError("transfer matrices are computed for synthetic arrays only")
    shape = (paths.num_rx, paths.num_tx, int(paths._max_num_paths) if _scatter_index(paths) is not None else 0)
    out = np.zeros((*shape, 4), np.complex64)
    index = _scatter_index(paths)
    if index is not None:
        extra = paths._paths_buffer.a[-1]
        if len(extra) != 4:
            raise RuntimeError("the solver did not compute transfer matrices (install() it first)")
        flat = out.reshape(-1, 4)
        for j, c in enumerate(extra):
            flat[index, j] = np.asarray(c.real, np.float32) + 1j * np.asarray(c.imag, np.float32)
    return out.reshape(*shape, 2, 2)


def vertices(paths) -> np.ndarray:
    """``float32 [max_depth, num_rx, num_tx, max_num_paths, 3]``: the interaction points (Sionna's
    ``Paths.vertices``), zero past a path's depth."""
    return np.asarray(paths.vertices, np.float32)
