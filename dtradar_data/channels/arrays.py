"""An antenna array as Sionna defines it (``sionna.rt.PlanarArray``), evaluated along stored paths without a scene.

The element positions and the element patterns are Sionna's own (``PlanarArray.normalized_positions``, its
``antenna_pattern.patterns``, Sionna's ``rotation_matrix``), so an array here means exactly what it means in a Sionna
scene; what this module adds is the change of basis a stored path needs: a pattern is evaluated in the array's local
frame and its field is expressed in the global spherical basis (θ̂, φ̂) of the path's direction, the basis of the
stored transfer matrices (:mod:`dtradar_data.rt.polarimetric`). Ports are ordered as Sionna orders them: pattern
(polarisation) first, then element, so port ``p * num_elements + e``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.scenes.model import PATTERNS, POLARIZATIONS


def _sionna():
    """``sionna.rt`` with the CPU Mitsuba variant set (the tracer's import: LLVM configured, variant picked)."""
    from dtradar_data.rt.tracer import _import_sionna

    mi, rt = _import_sionna("cpu")
    return mi, rt


@dataclass(frozen=True)
class Array:
    """A planar array: ``num_rows × num_cols`` elements of one ``pattern`` (``iso``, ``dipole``, ``hw_dipole``,
    ``tr38901``) in ``polarization`` (``V``, ``H``, ``VH``, ``cross``), spacings in wavelengths; Sionna's
    ``PlanarArray`` arguments. The paper: ``Array(8, 2, "tr38901", "VH")`` at the transmitter and
    ``Array(1, 1, "dipole", "V")`` at the receiver."""

    num_rows: int = 1
    num_cols: int = 1
    pattern: str = "iso"
    polarization: str = "V"
    vertical_spacing: float = 0.5
    horizontal_spacing: float = 0.5
    polarization_model: str = "tr38901_2"

    def __post_init__(self) -> None:
        problems = []
        for name in ("num_rows", "num_cols"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                problems.append(f"{name} {v!r} must be a positive int")
        if self.pattern not in PATTERNS:
            problems.append(f"pattern {self.pattern!r} is not one of {', '.join(PATTERNS)}")
        if self.polarization not in POLARIZATIONS:
            problems.append(f"polarization {self.polarization!r} is not one of {', '.join(POLARIZATIONS)}")
        if not (self.vertical_spacing > 0 and self.horizontal_spacing > 0):
            problems.append("spacings must be positive (in wavelengths)")
        if self.polarization_model not in ("tr38901_1", "tr38901_2"):
            problems.append(f"polarization_model {self.polarization_model!r} is not tr38901_1 or tr38901_2")
        if problems:
            raise InvalidSettingError("invalid antenna array: " + "; ".join(problems), hint="see Array's doc")

    @property
    def num_patterns(self) -> int:
        return 2 if self.polarization in ("VH", "cross") else 1

    @property
    def num_elements(self) -> int:
        return self.num_rows * self.num_cols

    @property
    def num_ports(self) -> int:
        """Antenna ports: elements × polarisations (Sionna's ``num_ant``)."""
        return self.num_elements * self.num_patterns

    def sionna(self):
        """This array as a ``sionna.rt.PlanarArray`` (for a scene's ``tx_array`` / ``rx_array``)."""
        _, rt = _sionna()
        return rt.PlanarArray(
            num_rows=self.num_rows,
            num_cols=self.num_cols,
            vertical_spacing=self.vertical_spacing,
            horizontal_spacing=self.horizontal_spacing,
            pattern=self.pattern,
            polarization=self.polarization,
            polarization_model=self.polarization_model,
        )

    def element_positions(self, wavelength_m: float, orientation_rad=(0.0, 0.0, 0.0)) -> np.ndarray:
        """``float64 [num_elements, 3]``: element positions relative to the array centre in the world frame, metres
        (Sionna's ``AntennaArray.rotate``)."""
        arr = self.sionna()
        p = arr.normalized_positions
        local = np.stack([np.asarray(p.x), np.asarray(p.y), np.asarray(p.z)], axis=1).astype(np.float64)
        return local * wavelength_m @ rotation_matrix(orientation_rad).T

    def field(self, theta: np.ndarray, phi: np.ndarray, orientation_rad=(0.0, 0.0, 0.0)) -> np.ndarray:
        """``complex128 [num_patterns, M, 2]``: each element pattern's field towards the directions (zenith
        ``theta``, azimuth ``phi``, world frame, rad), as components on the global θ̂ and φ̂ of those directions, for
        the array turned by ``orientation_rad`` (Sionna's yaw, pitch, roll)."""
        mi, _ = _sionna()
        theta = np.asarray(theta, np.float64).ravel()
        phi = np.asarray(phi, np.float64).ravel()
        rot = rotation_matrix(orientation_rad)
        k = _unit(theta, phi)
        k_local = k @ rot  # R^T k, row-wise
        th_l = np.arctan2(np.hypot(k_local[:, 0], k_local[:, 1]), k_local[:, 2])
        ph_l = np.arctan2(k_local[:, 1], k_local[:, 0])
        # the local spherical basis vectors, turned into the world frame, projected on the world θ̂, φ̂
        th_hat_w, ph_hat_w = _theta_hat(th_l, ph_l) @ rot.T, _phi_hat(ph_l) @ rot.T
        g_th, g_ph = _theta_hat(theta, phi), _phi_hat(phi)
        proj = np.array(
            [
                [np.sum(th_hat_w * g_th, axis=1), np.sum(ph_hat_w * g_th, axis=1)],
                [np.sum(th_hat_w * g_ph, axis=1), np.sum(ph_hat_w * g_ph, axis=1)],
            ]
        )  # [2 global, 2 local, M]
        out = np.empty((self.num_patterns, len(theta), 2), np.complex128)
        th_mi, ph_mi = mi.Float(th_l.astype(np.float32)), mi.Float(ph_l.astype(np.float32))
        for i, pattern in enumerate(self.sionna().antenna_pattern.patterns):
            c_th, c_ph = pattern(th_mi, ph_mi)
            c = np.stack([_complex(c_th, len(theta)), _complex(c_ph, len(theta))])  # [2 local, M]
            out[i] = np.einsum("glm,lm->mg", proj, c)
        return out


def _complex(c, n: int) -> np.ndarray:
    re = np.broadcast_to(np.asarray(c.real, np.float64), n)
    im = np.broadcast_to(np.asarray(c.imag, np.float64), n)
    return re + 1j * im


def _unit(theta, phi) -> np.ndarray:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def _theta_hat(theta, phi) -> np.ndarray:
    ct = np.cos(theta)
    return np.stack([ct * np.cos(phi), ct * np.sin(phi), -np.sin(theta)], axis=-1)


def _phi_hat(phi) -> np.ndarray:
    return np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(phi)], axis=-1)


def rotation_matrix(orientation_rad) -> np.ndarray:
    """Sionna's rotation (yaw α about z, pitch β about y, roll γ about x: ``R = Rz(α) Ry(β) Rx(γ)``), float64."""
    a, b, c = (float(v) for v in orientation_rad)
    sa, ca, sb, cb, sc, cc = np.sin(a), np.cos(a), np.sin(b), np.cos(b), np.sin(c), np.cos(c)
    return np.array(
        [
            [ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc],
            [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc],
            [-sb, cb * sc, cb * cc],
        ]
    )


def look_at_orientation(position_m, target_m) -> tuple[float, float, float]:
    """The orientation Sionna gives a device at ``position_m`` looking at ``target_m`` (``look_at``): local x towards
    the target, z kept in the vertical plane."""
    d = np.asarray(target_m, np.float64) - np.asarray(position_m, np.float64)
    d = d / np.linalg.norm(d)
    rho = np.hypot(d[0], d[1])
    theta = float(np.arctan2(rho, d[2]))
    phi = 0.0 if rho < 1e-7 else float(np.arctan2(d[1], d[0]))
    return (phi, theta - np.pi / 2, 0.0)
