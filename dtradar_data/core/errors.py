"""Typed errors of dtradar. Every message says what was wrong and how to fix it.

All public errors derive from :class:`DtradarError`, so callers can catch one type. Each subclass also derives
from the builtin it refines (``KeyError``, ``ValueError``, ``FileNotFoundError`` ...) so generic handlers keep working.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class DtradarError(Exception):
    """Base class of every error dtradar raises on purpose."""

    def __init__(self, message: str, *, hint: str | None = None):
        self.message = message
        self.hint = hint
        super().__init__(f"{message}\n  how to fix: {hint}" if hint else message)

    def __str__(self) -> str:  # KeyError would otherwise repr() the message
        return self.args[0]


class UnknownNameError(DtradarError, KeyError):
    """A dataset, scene, variant, preset or tag name that does not exist."""


class SceneFileError(DtradarError, ValueError):
    """A scene description file that is malformed or fails validation."""


class InvalidCoordinatesError(DtradarError, ValueError):
    """Coordinates outside the scene or grid, or otherwise impossible."""


class DatasetNotFoundError(DtradarError, FileNotFoundError):
    """A known dataset name that has not been built (or pulled) into the data root."""


class RevisionNotFoundError(DtradarError, LookupError):
    """A version tag or hash that does not exist for a dataset."""


class CorruptDatasetError(DtradarError, ValueError):
    """A dataset file that cannot be read, or whose content hash does not match."""


class SchemaMismatchError(DtradarError, ValueError):
    """A Parquet file whose columns or types differ from the expected schema."""


class MissingChannelDataError(DtradarError, LookupError):
    """Channels asked of a dataset version whose per-path table lacks the channel columns (built before them or
    without ``--rt.path-channels``): rebuilding it adds them."""


class MissingSceneError(DtradarError, LookupError):
    """The scene files asked of a dataset version that stores none (built before versions carried their scene, a
    moving twin, or a table made in memory): rebuilding it stores them."""


class RayTracerUnavailableError(DtradarError, RuntimeError):
    """Sionna RT / Mitsuba / a usable libLLVM is missing."""


class MissingDependencyError(DtradarError, ImportError):
    """An optional dependency is not installed."""


class InvalidSettingError(DtradarError, ValueError):
    """A setting that is out of range or does not fit the scene; the message names its command-line flag."""


class DataRootError(DtradarError, OSError):
    """The data root (``$DTRADAR_DATA_ROOT``) is not a usable folder: a file, or not writable."""


class HubError(DtradarError, RuntimeError):
    """The Hugging Face Hub could not be reached, or refused the request."""


class RayClusterError(DtradarError, ConnectionError):
    """A Ray cluster (``--ray-address`` or ``$RAY_ADDRESS``) where nothing answers, or not within the time allowed."""


class InUseError(DtradarError, RuntimeError):
    """A folder or dataset version that another live process is writing right now; the message names that process
    (its pid) and what it is doing, so the user can wait for it or stop it."""


def did_you_mean(name: str, choices: Iterable[str], n: int = 3) -> str:
    """A "did you mean ...?" phrase, or an empty string when nothing is close."""
    close = difflib.get_close_matches(name, list(choices), n=n, cutoff=0.5)
    return f"did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def unknown_name(kind: str, name: str, choices: Iterable[str]) -> UnknownNameError:
    """Build an :class:`UnknownNameError` for ``name`` with suggestions and the full list of choices."""
    choices = sorted(set(choices))
    suggestion = did_you_mean(name, choices)
    listing = ", ".join(choices) if choices else "(none)"
    message = f"unknown {kind} {name!r}" + (f"; {suggestion}" if suggestion else "")
    return UnknownNameError(message, hint=f"use one of: {listing}")
