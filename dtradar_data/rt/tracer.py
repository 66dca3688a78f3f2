"""Sionna RT for dtradar: with the patched solver it loads (:mod:`.batch_independent_solver`), the only module that
imports ``sionna.rt``, ``mitsuba`` or ``drjit``.

A :class:`RayTracer` owns the one mutable object, the Sionna scene, built once from a :class:`SceneSpec` (through the
Mitsuba XML that :mod:`dtradar_data.geometry.meshes` writes). Solvers are called with explicit keyword settings and a
seed taken from :class:`RTSettings`, and a cheap precondition check (:meth:`RayTracer.check_points`) runs before any
expensive trace. Results leave this module as plain numpy (:class:`PathBatch`), so everything downstream tests
without the ray tracer.

**Batch independence.** A receiver's paths are the same bytes whatever else is traced in the same PathSolver call
(tests/data/rt/test_batch_independence.py). Sionna 2.2's solver couples the receivers of a call three ways, and
:class:`~dtradar_data.rt.batch_independent_solver.BatchIndependentPathSolver` removes each (measured on the cubicle,
592 cells in one call vs calls of 128):

1. *The candidate hash table.* Specular chains are de-duplicated through two counter tables of
   ``max(max_num_paths_per_src, 1e6)`` slots shared by all receivers of the call, indexed by ``hash(chain, receiver
   index) % size`` (``sb_candidate_generator.py``, ``_shoot_and_bounce_loop``). A new chain whose slot another entry
   holds is dropped, so the more receivers a call has, the more of each receiver's paths are lost, and which ones
   depends on the others (591 of 592 rows differed, up to 29 paths; 1e7 slots: 464; 2.7e8 slots: 34). Here each
   receiver has its own region of :data:`~.batch_independent_solver.HASH_SLOTS_PER_RX` slots, indexed by the
   chain's hash alone.
2. *Shared SIMD packets.* The image method re-intersects every candidate's segments with the scene, with the
   candidates of all receivers packed side by side into the LLVM backend's ray packets. Where two objects' faces
   coincide (wood flush with concrete), which one a packet reports depends on the other rays of the packet, and so
   does the material a refraction goes through (5 of 592 rows, up to 0.6 dB). Here each receiver's candidates fill
   whole packets of 32 lanes of their own (padded with copies of its last one, dropped afterwards).
3. *The path buffer.* It holds ``max_num_paths_per_src`` candidates per call; when it fills, which survive depends
   on the call (NVlabs/sionna#1172). :meth:`RayTracer.trace` detects a full buffer and re-traces the call's
   receivers in halves, recursively; a receiver that fills it on its own keeps its (own) truncated paths.

The patched solver copies parts of one Sionna release: before a tracer loads anything for it, the installed
sionna-rt is checked against the releases it copies (:mod:`.sionna_version`).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dtradar_data.core.errors import InvalidCoordinatesError, InvalidSettingError, RayTracerUnavailableError
from dtradar_data.geometry.meshes import write_mitsuba_scene
from dtradar_data.rt.llvm import configure as configure_llvm
from dtradar_data.rt.settings import Device, RTSettings
from dtradar_data.rt.sionna_version import check_patched_sionna_rt
from dtradar_data.scenes.transmitters import check_one_array


@dataclass
class PathBatch:
    """All paths from the transmitter to ``N`` receivers, padded to ``P`` paths, as numpy arrays.

    ``a`` is Sionna's passband coefficient (``Paths.a``, no carrier phase) at the reference port pair (RX port 0,
    TX port 0); :mod:`.features` turns it into the baseband one. ``gain`` is ``|a|²`` averaged over
    all port pairs (‖H‖²_F / (N_r N_t)); angles are radians (zenith θ from +z, azimuth φ from +x); ``interactions``
    is ``[D, N, P]`` of Sionna ``InteractionType`` codes (0 = none).
    """

    valid: np.ndarray  # bool [N, P]
    a: np.ndarray  # complex64 [N, P]
    gain: np.ndarray  # float64 [N, P]
    tau: np.ndarray  # float64 [N, P]
    theta_t: np.ndarray
    phi_t: np.ndarray
    theta_r: np.ndarray
    phi_r: np.ndarray
    interactions: np.ndarray  # uint32 [D, N, P]
    frequency_hz: float
    # with --rt.path-channels (dtradar_data.rt.polarimetric), else None: receivers and paths are the last two axes of
    # every array field, which is how _concat and the batch helpers slice them
    transfer: np.ndarray | None = None  # complex64 [2, 2, N, P]: passband, receive port (V, H) x transmit port
    vertices: np.ndarray | None = None  # float32 [D, 3, N, P]: interaction points, zero past a path's depth

    @property
    def num_receivers(self) -> int:
        return self.valid.shape[0]


_MI = None  # the mitsuba module once a variant is set


def _import_sionna(device: Device, *, cpu_only: bool = False):
    """Configure LLVM, pick the Mitsuba variant, then import ``sionna.rt`` (order matters). ``cpu_only``: "auto"
    means the CPU even where a GPU is found (the batch-independent solver exists for LLVM only)."""
    global _MI
    if device != "cuda":
        configure_llvm()
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the install
        raise RayTracerUnavailableError(
            f"Mitsuba/Dr.Jit is not importable: {e}", hint="run `make setup` (or `pip install sionna-rt==2.2.0`)"
        ) from e
    use_cuda = _uses_cuda(dr, device, cpu_only=cpu_only)
    if device == "cuda" and not dr.has_backend(dr.JitBackend.CUDA):
        raise RayTracerUnavailableError(
            "device='cuda' requested but Dr.Jit finds no CUDA GPU", hint="use device='cpu' (or 'auto')"
        )
    variant = "cuda_ad_mono_polarized" if use_cuda else "llvm_ad_mono_polarized"
    if mi.variant() != variant:
        mi.set_variant(variant)
    try:
        import sionna.rt as rt
    except Exception as e:  # pragma: no cover
        raise RayTracerUnavailableError(f"sionna.rt failed to import: {e}", hint="run `make setup`") from e
    _MI = mi
    return mi, rt


def _uses_cuda(dr, device: Device, *, cpu_only: bool) -> bool:
    return device == "cuda" or (device == "auto" and not cpu_only and dr.has_backend(dr.JitBackend.CUDA))


def trace_device(settings: RTSettings) -> str:
    """``"cpu"`` or ``"cuda"``: where a :class:`RayTracer` made with ``settings`` traces, ``--rt.device auto``
    resolved as the tracer resolves it, known before any scene loads (a partial build records it:
    :mod:`dtradar_data.pipeline.resume`). Only ``auto`` with Sionna's own solver asks Dr.Jit for a GPU."""
    if settings.device != "auto":
        return settings.device
    if settings.batch_independent:  # implemented for LLVM only: auto means the CPU (see _import_sionna)
        return "cpu"
    configure_llvm()  # before Dr.Jit's first import, as _import_sionna does
    try:
        import drjit as dr
    except ImportError as e:  # pragma: no cover - depends on the install
        raise RayTracerUnavailableError(
            f"Dr.Jit is not importable: {e}", hint="run `make setup` (or `pip install sionna-rt==2.2.0`)"
        ) from e
    return "cuda" if _uses_cuda(dr, "auto", cpu_only=False) else "cpu"


def _pose(tx) -> dict:
    """The Transmitter keywords of ``tx``'s power and pose: an exact orientation (a pose-error twin) wins over the
    look-at point."""
    if tx.orientation_deg is not None:
        return {"power_dbm": tx.power_dbm, "orientation": [math.radians(v) for v in tx.orientation_deg]}
    return {"power_dbm": tx.power_dbm, **({"look_at": list(tx.look_at_m)} if tx.look_at_m is not None else {})}


def active_variant() -> str | None:
    return _MI.variant() if _MI is not None else None


class RayTracer:
    """A Sionna scene built from a :class:`SceneSpec`, with the paper's transmitter and receiver arrays."""

    def __init__(self, spec, settings: RTSettings = RTSettings(), *, scene_dir: Path | None = None):
        if settings.batch_independent:
            check_patched_sionna_rt()  # first: a wrong release fails before the scene loads, not deep in a trace
        # Sionna's scene has one array for every transmitter: readers refuse other files; a spec made in code here
        check_one_array(getattr(spec, "transmitters", (spec.tx,)), spec.name)
        self.spec = spec
        self.settings = settings
        self.mi, self.rt = _import_sionna(settings.device, cpu_only=settings.batch_independent)
        self._tmp = None
        if scene_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="dtradar-scene-")
            scene_dir = Path(self._tmp.name)
        xml = write_mitsuba_scene(spec, Path(scene_dir))
        rt = self.rt
        self.scene = rt.load_scene(str(xml), merge_shapes=True)
        self.scene.frequency = settings.frequency_hz
        tx = spec.tx  # the transmitter array is part of the scene (paper: 8x2 tr38901 VH, on the ceiling)
        self.scene.tx_array = rt.PlanarArray(
            num_rows=tx.num_rows, num_cols=tx.num_cols, pattern=tx.pattern, polarization=tx.polarization
        )
        self.scene.rx_array = rt.PlanarArray(
            num_rows=1, num_cols=1, pattern=settings.rx_pattern, polarization=settings.rx_polarization
        )
        transmitters = getattr(spec, "transmitters", (tx,))
        for k, t in enumerate(transmitters):  # one trace covers all of them: the solver shoots from each
            self.scene.add(rt.Transmitter("tx" if k == 0 else f"tx{k}", position=list(t.position_m), **_pose(t)))
        self.num_tx = len(transmitters)
        if settings.batch_independent:
            if self.variant.startswith("cuda"):
                # Sionna's deterministic CUDA generator has its own shared hash table; not patched (no GPU here)
                raise InvalidSettingError(
                    "--rt.batch-independent is implemented for the CPU (LLVM) backend only",
                    hint="trace with --rt.device auto or cpu, or with --rt.no-batch-independent (Sionna's own solver)",
                )
            # imports Sionna's internals, so only now that _import_sionna has picked the variant
            from dtradar_data.rt.batch_independent_solver import BatchIndependentPathSolver

            self._solver = BatchIndependentPathSolver()
        else:
            self._solver = rt.PathSolver(deterministic=settings.deterministic and self.variant.startswith("cuda"))
        if settings.path_channels:
            from dtradar_data.rt import polarimetric  # imports Sionna's internals: only once the variant is set

            polarimetric.install(self._solver)
        self._rx_names: list[str] = []
        self.solver_calls = 0
        """PathSolver calls so far."""
        self.overflowed_calls = 0
        """Calls whose path buffer filled (re-traced in halves when they had more than one receiver)."""
        self.last_retrace_depth = np.zeros(0, np.int8)
        """Per receiver of the last :meth:`trace`: how many times its call was halved because the buffer filled
        (0: traced in the call it was given to); -1 marks a receiver that filled the buffer on its own."""

    @property
    def variant(self) -> str:
        return self.mi.variant()

    # -- the cheap precondition check ----------------------------------------------------------------------------
    def check_points(self, points: np.ndarray) -> None:
        """Reject receiver positions that are not finite or lie outside the scene's horizontal extent."""
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InvalidCoordinatesError(
                f"receiver positions must have shape [N, 3], got {points.shape}",
                hint="pass one (x, y, z) row per receiver",
            )
        if not np.isfinite(points).all():
            raise InvalidCoordinatesError(
                "receiver positions contain NaN or infinity", hint="check the grid origin and cell size"
            )
        bbox = self.scene.mi_scene.bbox()
        lo, hi = np.array(bbox.min, dtype=float).ravel(), np.array(bbox.max, dtype=float).ravel()
        # x/y only: receivers may float above a flat scene (z is checked against the grid spec elsewhere)
        outside = np.any((points[:, :2] < lo[:2] - 1e-6) | (points[:, :2] > hi[:2] + 1e-6), axis=1)
        if outside.any():
            first = points[np.argmax(outside)]
            raise InvalidCoordinatesError(
                f"{int(outside.sum())} receiver(s) lie outside the scene bounds {lo[:2].round(2)}..{hi[:2].round(2)}, "
                f"e.g. {first.round(3)}",
                hint="fix the grid (x0_m, y0_m, cell_m, nx, ny) or rx_height_m in the scene file",
            )

    # -- tracing -------------------------------------------------------------------------------------------------
    def _set_receivers(self, points: np.ndarray) -> None:
        for name in self._rx_names:
            self.scene.remove(name)
        self._rx_names = [f"rx{i}" for i in range(len(points))]
        for name, p in zip(self._rx_names, points):
            self.scene.add(self.rt.Receiver(name, position=[float(v) for v in p]))

    def trace(self, points: np.ndarray) -> PathBatch:
        """Trace paths from the transmitter (transmitter 0 of several) to every point (batch in the caller). One
        PathSolver call, or more where the path buffer fills: then the receivers are re-traced in halves until no
        call fills it, so that a receiver's paths do not depend on the receivers traced with it (see the module
        doc)."""
        return self.trace_each(points)[0]

    def trace_each(self, points: np.ndarray) -> list[PathBatch]:
        """:meth:`trace` for every transmitter of the scene at once: one :class:`PathBatch` per transmitter, from
        the same PathSolver calls."""
        points = np.asarray(points, dtype=np.float64)
        self.check_points(points)
        depth = np.zeros(len(points), np.int8)
        parts = self._trace_split(points, depth, 0)
        self.last_retrace_depth = depth
        if len(parts) == 1:
            return parts[0]
        return [_concat([p[k] for p in parts]) for k in range(self.num_tx)]

    def _trace_split(self, points: np.ndarray, depth: np.ndarray, level: int) -> list[list[PathBatch]]:
        batch, full = self._trace_once(points)
        if not full:
            depth[:] = level
            return [batch]
        if len(points) == 1:
            depth[:] = -1
            return [batch]
        half = len(points) // 2
        return self._trace_split(points[:half], depth[:half], level + 1) + self._trace_split(
            points[half:], depth[half:], level + 1
        )

    def _trace_once(self, points: np.ndarray) -> tuple[list[PathBatch], bool]:
        """One PathSolver call: the paths of each transmitter and whether the path buffer filled."""
        self._set_receivers(points)
        import drjit as dr

        pin = self.settings.deterministic and self.variant.startswith("llvm")
        threads = dr.thread_count()
        if pin:
            dr.set_thread_count(1)
        try:
            paths = self._solver(self.scene, **self.settings.solver_kwargs())
            full = bool(getattr(self._solver, "buffer_full", False))
            self.solver_calls += 1
            self.overflowed_calls += full
            return [self._to_numpy(paths, len(points), k) for k in range(self.num_tx)], full
        finally:
            if pin:
                dr.set_thread_count(threads)

    def _to_numpy(self, paths, n: int, k: int = 0) -> PathBatch:
        """Transmitter ``k``'s paths of one solver call (the rows of every transmitter share the call's width)."""
        a_re, a_im = (np.asarray(x, dtype=np.float32) for x in paths.a)
        a = a_re + 1j * a_im
        if self.settings.synthetic_array:
            # a: [rx, rx_ant, tx, tx_ant, P]; geometry: [rx, tx, P]; interactions: [D, rx, tx, P]
            # contiguous, as transmitter 0 of a one-transmitter call is: numpy's mean sums a strided view in another
            # order, and a cell's gain would change in its last bit with the transmitters beside it
            a = np.ascontiguousarray(a[:, :, k, :, :])
            ref = a[:, 0, 0, :]
            gain = np.mean(np.abs(a) ** 2, axis=(1, 2))

            def geo(x):
                return np.asarray(x)[:, k, :]

            inter = np.asarray(paths.interactions)[:, :, k, :]
        else:
            # a: [rx, rx_ant, tx, tx_ant, P]; geometry: [rx, rx_ant, tx, tx_ant, P]: use the reference ports
            a = np.ascontiguousarray(a[:, :, k, :, :])
            ref = a[:, 0, 0, :]
            gain = np.mean(np.abs(a) ** 2, axis=(1, 2))

            def geo(x):
                return np.asarray(x)[:, 0, k, 0, :]

            inter = np.asarray(paths.interactions)[:, :, 0, k, 0, :]
        valid = geo(paths.valid).astype(bool)
        batch = PathBatch(
            valid=valid,
            a=ref.astype(np.complex64),
            gain=gain.astype(np.float64),
            tau=geo(paths.tau).astype(np.float64),
            theta_t=geo(paths.theta_t).astype(np.float64),
            phi_t=geo(paths.phi_t).astype(np.float64),
            theta_r=geo(paths.theta_r).astype(np.float64),
            phi_r=geo(paths.phi_r).astype(np.float64),
            interactions=inter.astype(np.uint32),
            frequency_hz=float(self.settings.frequency_hz),
        )
        if self.settings.path_channels:  # synthetic arrays only (RTSettings refuses the rest)
            from dtradar_data.rt import polarimetric

            t = polarimetric.transfer_matrices(paths)[:, k]  # [N, P, 2, 2]
            batch.transfer = np.ascontiguousarray(t.transpose(2, 3, 0, 1))
            v = polarimetric.vertices(paths)[:, :, k]  # [D, N, P, 3]
            batch.vertices = np.ascontiguousarray(v.transpose(0, 3, 1, 2))
        if batch.valid.shape[0] != n:  # pragma: no cover - guards against a Sionna layout change
            raise RuntimeError(f"Sionna returned {batch.valid.shape[0]} receivers for {n} requested")
        return batch

    def radio_map(
        self,
        *,
        centre_m: tuple[float, float, float],
        size_m: tuple[float, float],
        cell_m: float,
        samples_per_tx: int = 2_000_000,
        settings: RTSettings | None = None,
        precoding_vec=None,
    ) -> np.ndarray:
        """Path gain (linear) on a horizontal plane with RadioMapSolver: ``float64[ny, nx]`` (row 0 = lowest y); with
        several transmitters, the strongest transmitter's at each point.
        ``settings``: the interactions, depth and seed (default this tracer's); ``precoding_vec``: Sionna's
        ``(real, imag)`` precoding of the TX ports (default its own: every port 1/sqrt(N))."""
        rt, mi = self.rt, self.mi
        s = settings or self.settings
        rm = rt.RadioMapSolver()(
            self.scene,
            center=mi.Point3f(*centre_m),
            orientation=mi.Point3f(0, 0, 0),
            size=mi.Point2f(*size_m),
            cell_size=mi.Point2f(cell_m, cell_m),
            precoding_vec=precoding_vec,
            samples_per_tx=samples_per_tx,
            max_depth=s.max_depth,
            los=s.los,
            specular_reflection=s.specular_reflection,
            diffuse_reflection=s.diffuse_reflection,
            refraction=s.refraction,
            diffraction=s.diffraction,
            seed=s.seed,
        )
        gain = np.asarray(rm.path_gain, dtype=np.float64)  # [transmitters, ny, nx]
        return gain[0] if len(gain) == 1 else gain.max(axis=0)  # several: the strongest one's (the best server)

    def close(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


def _concat(parts: list[PathBatch]) -> PathBatch:
    """Receivers of several :class:`PathBatch` in order, padded to the widest (invalid, zero padding)."""
    import dataclasses

    width = max(p.valid.shape[1] for p in parts)

    def pad(x: np.ndarray) -> np.ndarray:
        return np.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, width - x.shape[-1])])

    out = {}
    for f in dataclasses.fields(PathBatch):
        values = [getattr(p, f.name) for p in parts]
        if isinstance(values[0], np.ndarray):  # receivers are the second-to-last axis of every array field
            out[f.name] = np.concatenate([pad(v) for v in values], axis=values[0].ndim - 2)
        else:
            out[f.name] = values[0]
    return PathBatch(**out)


def smoke_test() -> str:
    """Start the ray-tracing backend and run one tiny JIT kernel; returns a one-line report."""
    mi, _ = _import_sionna("auto")
    import drjit as dr

    x = dr.arange(mi.Float, 8)
    total = float(dr.sum(x * x)[0] if hasattr(dr.sum(x * x), "__getitem__") else dr.sum(x * x))
    if abs(total - 140.0) > 1e-6:  # pragma: no cover
        raise RayTracerUnavailableError(
            f"Dr.Jit smoke test computed {total}, expected 140",
            hint="the LLVM backend is broken: reinstall with `make setup`",
        )
    return f"Sionna RT ready: variant {mi.variant()}, DRJIT_LIBLLVM_PATH={os.environ.get('DRJIT_LIBLLVM_PATH')}"
