"""Ray-tracing settings: a frozen dataclass whose fields (except device and determinism) feed the version hash.

No Sionna import here, so configs, the CLI and the store can use the settings without the ray tracer.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from typing import Any, Literal

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.schema import CHANNEL_SCHEMA_VERSION
from dtradar_data.scenes.materials import ITU_VALID_GHZ, material_valid_at
from dtradar_data.scenes.model import PATTERNS, POLARIZATIONS

Device = Literal["auto", "cpu", "cuda"]


#: What --rt.batch-independent means, hashed into the version: change it with anything that changes its rows
#: (dtradar_data.rt.batch_independent_solver.HASH_SLOTS_PER_RX, the packet width, the patched Sionna code).
BATCH_INDEPENDENT_ENGINE = "dtradar-1: 65536 hash slots per receiver, 32-lane packets, buffer split (sionna-rt 2.2.0)"


#: What --rt.path-channels stores, hashed into the version (and recorded in meta.json's ``rt``): change it with the
#: channel columns (dtradar_data.core.schema.CHANNEL_SCHEMA_VERSION) or how they are computed.
PATH_CHANNELS_ENGINE = (
    "dtradar-1: 2x2 transfer at isotropic V/H ports, world frame, baseband; interaction points; "
    f"channel columns v{CHANNEL_SCHEMA_VERSION}"
)


def flag(name: str) -> str:
    """The ``build`` flag of a settings field (tyro nests them under ``--rt.``)."""
    return "--rt." + name.replace("_", "-")


def _wrong_types(settings: RTSettings) -> list[str]:
    """Fields whose value is not of their type (a string or a bool for a number, a fraction for a count): the Python
    API's mistakes, since the command line converts every value (a NaN included; the range checks refuse it). Numbers
    of another numeric type (an int frequency, a NumPy integer) are converted in place, so equal settings hash
    equally."""
    problems = []
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if f.type in ("float", "int"):
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
            ok = ok and (f.type == "float" or isinstance(value, numbers.Integral))
            if ok:
                object.__setattr__(settings, f.name, float(value) if f.type == "float" else int(value))
        elif f.type == "bool":
            ok = isinstance(value, bool)
        else:
            ok = isinstance(value, str)
        if not ok:
            problems.append(f"{flag(f.name)} {value!r} is not a{'n' if f.type == 'int' else ''} {f.type}")
    return problems


@dataclass(frozen=True)
class RTSettings:
    """Ray-tracing settings. Every field except ``device`` and ``deterministic`` feeds the dataset version hash."""

    frequency_hz: float = 2.4e9
    """Carrier frequency (the paper: 2.4 GHz)."""
    max_depth: int = 5
    """Maximum number of interactions per path (the paper: 5)."""
    samples_per_src: int = 10_000
    """Rays shot from the transmitter per trace; chosen from `make bench-rt` (see README)."""
    max_num_paths_per_src: int = 1_000_000
    """Sionna's buffer of candidate paths per source; it also sizes the hash table that de-duplicates specular
    chains, so a small one silently drops paths. Measured on the cubicle at 1e4 samples: 1e6 keeps 47 819 paths in
    2.5 s, 1e7 keeps 58 652 in 6.8 s (2.3 GB); the strongest paths are the same. Use 1e7 with 1e6 samples."""
    seed: int = 42
    """Seed of the ray sampler; the same scene, settings and seed give identical tables."""
    los: bool = True
    """Trace the line-of-sight path."""
    specular_reflection: bool = True
    """Trace specular reflections (walls, floor, ceiling, objects)."""
    diffuse_reflection: bool = False
    """Trace diffuse reflections (off by default, like Sionna; costly)."""
    refraction: bool = True
    """Trace transmission through objects (ITU slab model)."""
    diffraction: bool = False
    """Trace first-order edge diffraction (off by default, like Sionna)."""
    synthetic_array: bool = True
    """Trace from the array centre and apply element phase shifts (Sionna's default, and much cheaper)."""
    rx_pattern: str = "dipole"
    rx_polarization: str = "V"
    """Receiver: one vertical short dipole (the paper's 1x1 dipole)."""
    batch_size: int = 1024
    """Receivers per PathSolver call. Each call shoots all samples_per_src rays again, so bigger batches are
    cheaper per cell; with Sionna's own solver (--rt.no-batch-independent) results depend on the batch partition
    (measured), so it is part of the version; batch-independent tracing, the default, leaves it out."""
    batch_independent: bool = True
    """Trace every receiver independently of the others in its PathSolver call (dtradar_data.rt.tracer: a hash
    region, SIMD packets and a buffer check of its own): a cell's rows are the same bytes whatever batch it is
    traced in, so batch_size leaves the version. The default since it was measured more accurate (median total-gain
    error against a 1e6-sample reference 0.011 dB, Sionna's own solver 0.153 dB: docs/ray-tracing.md); it keeps the
    ~25 % of paths Sionna's shared hash table drops and costs time (cubicle ~1.5-2x, a Dallas quadrant ~1.15x).
    CPU (LLVM) only: with --rt.device auto it traces on the CPU even where a GPU is found;
    --rt.no-batch-independent is Sionna's own solver (CPU or GPU), the engine of the versions built before."""
    path_channels: bool = False
    """Also store, per path, the 2x2 polarimetric transfer matrix between isotropic V/H ports and the interaction
    points (paths.parquet's channel columns, dtradar_data.rt.polarimetric), so that the channel of any antenna array
    can be generated from the dataset (dtradar_data.channels). Off by default for now: it adds a setting to the
    version hash, so versions built without it keep theirs. Needs --rt.synthetic-array and the per-path table."""
    deterministic: bool = True
    """Bit-identical tables for the same inputs. On the CPU: pin Dr.Jit to one thread while tracing (its
    multi-threaded path collection changes the weak-path count from run to run; measured no slower on 2 cores, and
    lighter than Sionna's deterministic solver: 7.5 vs 17.8 GB at 1e5 samples). On CUDA: Sionna's
    PathSolver(deterministic=True) (not measured here: no GPU)."""
    device: Device = "auto"
    """"auto" uses CUDA when Dr.Jit finds a GPU, else the CPU (LLVM)."""

    def __post_init__(self) -> None:
        # Checked here, before the first trace; messages name the command-line flag (`build --rt.<name>`).
        wrong_type = _wrong_types(self)
        if wrong_type:  # the range checks below would fail on them with a TypeError, not naming the flag
            raise InvalidSettingError(
                "invalid ray-tracing settings: " + "; ".join(wrong_type),
                hint="see `python -m dtradar_data build --help` for the accepted values",
            )
        problems = []
        if not 1e8 <= self.frequency_hz <= 1e11:
            problems.append(f"{flag('frequency_hz')} {self.frequency_hz:g} is outside 100 MHz .. 100 GHz")
        if not 0 <= self.max_depth <= 10:
            problems.append(f"{flag('max_depth')} {self.max_depth} must be in 0..10")
        for name in ("samples_per_src", "batch_size", "max_num_paths_per_src"):
            if getattr(self, name) < 1:
                problems.append(f"{flag(name)} {getattr(self, name)} must be positive")
        if not 0 <= self.seed < 2**32:  # Sionna's samplers take an unsigned 32-bit seed
            problems.append(f"{flag('seed')} {self.seed} must be in 0 .. 2**32-1")
        if self.rx_pattern not in PATTERNS:
            problems.append(
                f"{flag('rx_pattern')} {self.rx_pattern!r} is not an antenna pattern ({', '.join(PATTERNS)})"
            )
        if self.rx_polarization not in POLARIZATIONS:
            problems.append(
                f"{flag('rx_polarization')} {self.rx_polarization!r} is not a polarization ({', '.join(POLARIZATIONS)})"
            )
        if self.path_channels and not self.synthetic_array:
            problems.append(f"{flag('path_channels')} needs {flag('synthetic_array')} (one transfer matrix per path)")
        if self.device not in ("auto", "cpu", "cuda"):
            problems.append(f"{flag('device')} {self.device!r} must be 'auto', 'cpu' or 'cuda'")
        if problems:
            raise InvalidSettingError(
                "invalid ray-tracing settings: " + "; ".join(problems),
                hint="see `python -m dtradar_data build --help` for the accepted values",
            )

    def check_scene(self, spec) -> None:
        """Settings that are in range but that ``spec`` cannot be traced with: Sionna would fail (or, for an
        undefined material, raise deep inside) only after the scene was loaded."""
        # getattr: city specs also carry prisms (buildings, roads), indoor ones only boxes
        materials = {o.material for o in (*spec.objects, *getattr(spec, "prisms", ()))}
        undefined = sorted(m for m in materials if m in ITU_VALID_GHZ and not material_valid_at(m, self.frequency_hz))
        if undefined:
            ranges = ", ".join(f"{m} {ITU_VALID_GHZ[m][0]:g}-{ITU_VALID_GHZ[m][1]:g} GHz" for m in undefined)
            raise InvalidSettingError(
                f"{flag('frequency_hz')} {self.frequency_hz:g}: ITU-R P.2040 does not define the material(s) of "
                f"{spec.name} at {self.frequency_hz / 1e9:g} GHz ({ranges})",
                hint="pick a frequency inside every material's range (the paper: 2.4e9)",
            )

    def hashed(self) -> dict[str, Any]:
        """The settings that determine the result (and so the dataset version)."""
        d = dataclasses.asdict(self)
        d.pop("device")
        d.pop("deterministic")  # changes only run-to-run noise, not what the table means
        if self.batch_independent:
            d.pop("batch_size")  # the partition no longer changes a row (tests/data/rt/test_batch_independence.py)
            d["batch_independent"] = BATCH_INDEPENDENT_ENGINE
        else:
            d.pop("batch_independent")  # the versions traced with Sionna's own solver keep their hashes
        if self.path_channels:
            d["path_channels"] = PATH_CHANNELS_ENGINE
        else:
            d.pop("path_channels")  # versions built without the channel columns keep their hashes
        return d

    def solver_kwargs(self) -> dict[str, Any]:
        return dict(
            max_depth=self.max_depth,
            max_num_paths_per_src=self.max_num_paths_per_src,
            samples_per_src=self.samples_per_src,
            synthetic_array=self.synthetic_array,
            los=self.los,
            specular_reflection=self.specular_reflection,
            diffuse_reflection=self.diffuse_reflection,
            refraction=self.refraction,
            diffraction=self.diffraction,
            seed=self.seed,
        )
