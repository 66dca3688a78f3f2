"""Settings shared by every job: the twin to work on, how it is observed and rewarded, where the run goes.

:class:`TwinConfig` is the one base of every config (:class:`~dtradar_rl.train.config.DQNConfig`,
:class:`~dtradar_rl.offline.logged.LogConfig`, :class:`~dtradar_rl.offline.trainer.OfflineConfig`,
:class:`~dtradar_rl.experiments.adapt.AdaptConfig`, ...); each field's docstring is its ``--help`` line.
``validate()`` checks every setting before the first expensive step and names the offending ``--flag``.
"""

from __future__ import annotations

import contextvars
import dataclasses
import math
import numbers
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Annotated, Any

import torch
import tyro

from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.task.observations import check_preset
from dtradar_rl.task.rewards import check_reward

INDOOR_SCENES = ("cubicle", "meeting")

#: A field whose help text says what its default means (``--out``: "default runs/<scene>/<trainer>"): tyro's own
#: ``(default: '')`` after it would state the default a second time, as an empty string.
DEFAULT_IN_HELP = tyro.conf.arg(help_behavior_hint="")


class ConfigError(InvalidSettingError):
    """A training or evaluation setting that is out of range (an :class:`InvalidSettingError`: exit status 2)."""


#: True while the command line parses: the configs tyro makes skip their range checks until the command runs
#: ``validate()``, so a bad flag is the boundary's one ``error:`` line (exit 2), not tyro's usage box.
_CHECKS_DEFERRED = contextvars.ContextVar("dtradar_rl_config_checks_deferred", default=False)


@contextmanager
def deferred_checks(deferred: bool = True) -> Iterator[None]:
    """Within the block, configs are made without their range checks (``deferred=False``: with them again)."""
    token = _CHECKS_DEFERRED.set(deferred)
    try:
        yield
    finally:
        _CHECKS_DEFERRED.reset(token)


def flag(name: str) -> str:
    """The command-line flag of a config field (tyro writes ``lr_end`` as ``--lr-end``)."""
    return "--" + name.replace("_", "-")


def check_device(name: str) -> torch.device:
    """``name`` as a torch device, or :class:`ConfigError` when it is malformed or not present on this machine."""
    try:
        device = torch.device(name)
    except RuntimeError as e:
        raise ConfigError(f"--device {name!r} is not a torch device ({e})", hint="use cpu, cuda or cuda:<n>") from e
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(
            f"--device {name} asked for, but torch sees no CUDA GPU on this machine", hint="use --device cpu"
        )
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise ConfigError(
            f"--device {name}: this machine has {torch.cuda.device_count()} CUDA device(s)", hint="use --device cuda:0"
        )
    if device.type not in ("cpu", "cuda"):
        raise ConfigError(f"--device {name}: only cpu and cuda are supported", hint="use --device cpu")
    return device


def check_unique(values, name: str) -> None:
    """:class:`ConfigError` naming ``--<name>`` when ``values`` repeats one (a repeated seed or scene would count one
    run twice, and two runs would share one output folder)."""
    seen, repeated = set(), []
    for v in values:
        if v in seen and v not in repeated:
            repeated.append(v)
        seen.add(v)
    if repeated:
        listed = " ".join(str(v) for v in dict.fromkeys(values))
        raise ConfigError(
            f"{flag(name)} repeats {', '.join(repr(v) for v in repeated)}: each value is one run (or one column), "
            "and a repeated one would be counted twice",
            hint=f"name each once, e.g. {flag(name)} {listed}",
        )


@dataclass(frozen=True)
class Config:
    """The one base of every config: checks that name the ``--flag``, and a JSON round trip.

    A config checks its numbers when it is made (:meth:`check_ranges`, from ``__post_init__``: a wrong type, NaN or
    infinity, a value out of range); :meth:`validate` adds what depends on the machine or the store (devices, names)
    before the first expensive step."""

    def __post_init__(self) -> None:
        if not _CHECKS_DEFERRED.get():
            self.check_ranges()

    def check_ranges(self) -> None:
        """Every field of type ``int`` or ``float`` holds a finite number of that type (an int for an int: no bool,
        no 2.5); subclasses extend this with their ranges (calling ``super()``). No I/O, no device: a saved config
        read back on another machine passes it."""
        for f in dataclasses.fields(self):
            kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            v = getattr(self, f.name)
            if kind == "int" and (isinstance(v, bool) or not isinstance(v, numbers.Integral)):
                raise ConfigError(f"{flag(f.name)} must be an integer, got {v!r}")
            if kind == "float":
                if isinstance(v, bool) or not isinstance(v, numbers.Real):
                    raise ConfigError(f"{flag(f.name)} must be a number, got {v!r}")
                if not math.isfinite(v):
                    raise ConfigError(f"{flag(f.name)} must be a finite number, got {v}")

    def check_at_least(self, minimum: int, *names: str) -> None:
        for name in names:
            if getattr(self, name) < minimum:
                raise ConfigError(f"{flag(name)} must be >= {minimum}, got {getattr(self, name)}")

    def check_within(self, low: float, high: float, *names: str, open_interval: bool = False) -> None:
        for name in names:
            v = getattr(self, name)
            inside = low < v < high if open_interval else low <= v <= high
            if not inside:
                brackets = "()" if open_interval else "[]"
                raise ConfigError(f"{flag(name)} must be in {brackets[0]}{low}, {high}{brackets[1]}, got {v}")

    def validate(self):
        """Check every setting before the first expensive step; subclasses extend this and return ``self``."""
        self.check_ranges()
        return self

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]):
        """The config saved by :meth:`to_dict` (JSON lists back to tuples; keys of other versions ignored)."""
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names})


@dataclass(frozen=True)
class JobConfig(Config):
    """A job on one scene's twin: which twin, the seed, the threads, where its files go."""

    scene: str = "cubicle"
    """scene to train on; the dataset is <scene>/<variant> (synthetic = a 42x18 stand-in, no ray tracer)"""
    variant: str = "blueprint"
    """twin to train on (the paper trains on the blueprint)"""
    seed: int = 0
    """seed of the network, the environment and exploration"""
    threads: int = 0
    """torch CPU threads (0 = auto: up to 2, fewer when other processes keep cores busy; see dtradar_rl.task.runtime)"""
    out: Annotated[str, DEFAULT_IN_HELP] = ""
    """output directory (default: runs/<scene>/<trainer>)"""
    verbose: bool = True
    """print progress"""

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(0, "threads", "seed")


@dataclass(frozen=True)
class TwinConfig(JobConfig):
    """The twin a trainer works on and how it observes it."""

    revision: Annotated[str | None, DEFAULT_IN_HELP] = None
    """dataset version tag or hash (default: the newest)"""
    obs: str = "neighbors"
    """observation preset: paper (10 inputs, no target), goal (+ target), neighbors (+ neighbouring cells' radio)"""
    reward: str = "geodesic"
    """reward: paper (exact), scaled, euclidean or geodesic (shaped; see dtradar_rl.task.rewards)"""
    max_steps: int = 0
    """episode step limit (truncation); 0 = 4 * (nx + ny)"""
    num_envs: int = 256
    """robots stepped together in the batched environment"""
    hidden: tuple[int, ...] = (256, 256)
    """sizes of the dense ReLU hidden layers"""
    device: str = "cpu"
    """torch device (cpu, cuda, cuda:1)"""

    @property
    def dataset_name(self) -> str:
        return f"{self.scene}/{self.variant}" + (f"@{self.revision}" if self.revision else "")

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(1, "num_envs")
        self.check_at_least(0, "max_steps")
        if (
            not self.hidden
            or any(isinstance(h, bool) or not isinstance(h, numbers.Integral) for h in self.hidden)
            or min(self.hidden) < 1
        ):
            raise ConfigError(
                f"--hidden must list positive layer sizes, got {self.hidden}", hint="e.g. --hidden 256 256"
            )

    def validate(self):
        """Check the shared settings; subclasses extend this and return ``self``."""
        super().validate()
        check_preset(self.obs)
        check_reward(self.reward)
        check_device(self.device)
        return self
