"""Scene names that changed, kept working as aliases: a twin with several transmitters says how many in its name,
``<place>-<N>tx`` after the place it covers (``sionna-munich-10tx``, ``dallas-3tx-q3``: a city's quadrant follows its
city's name, as for ``dallas-q3``), one separator throughout. Before, ``cells`` meant the transmitters
(``dallas-cells-q3``) and Munich's mixed ``-`` and ``_`` (``sionna-munich_cells``).

An old name is still taken wherever a scene or dataset is named, and says once per process that it is an old name.
Data stored under an old name stays where it is: :func:`stored_or_current` keeps the old name when only its data is
in the store.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

#: old scene name -> its name now: build inputs (``sionna:`` spelling, a whole city) and dataset scenes alike
RENAMED: dict[str, str] = {
    "sionna:munich_cells": "sionna:munich-10tx",
    "sionna-munich_cells": "sionna-munich-10tx",
    "dallas-cells": "dallas-3tx",
    **{f"dallas-cells-q{i}": f"dallas-3tx-q{i}" for i in range(1, 5)},
}

_said: set[str] = set()


def _note(old: str, new: str, kept: bool) -> None:
    if old in _said:
        return
    _said.add(old)
    then = "its data is stored under the old name, used as is" if kept else f"using {new!r}"
    print(
        f"note: {old!r} is the old name of {new!r} (the transmitters are counted in the name now); {then}",
        file=sys.stderr,
    )


def current_scene(name: str) -> str:
    """``name`` as it is called now (itself when it was never renamed); an old name says so once."""
    new = RENAMED.get(name)
    if new is None:
        return name
    _note(name, new, kept=False)
    return new


def stored_or_current(name: str, is_stored: Callable[[str], bool]) -> str:
    """The dataset scene to open for ``name``: its current name, unless only the other spelling (old or new) has data
    in the store (``is_stored(scene)``), as a store filled before the rename has; an old name says so once."""
    old_of = {new: old for old, new in RENAMED.items()}
    new = RENAMED.get(name)
    if new is None:
        old = old_of.get(name)
        return old if old is not None and not is_stored(name) and is_stored(old) else name
    kept = is_stored(name) and not is_stored(new)
    _note(name, new, kept)
    return name if kept else new


__all__ = ["RENAMED", "current_scene", "stored_or_current"]
