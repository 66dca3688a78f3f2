"""Datasets for navigation: stored twins by name, and synthetic stand-ins that need no ray tracer.

Names
-----
``"<scene>/<variant>[@<revision>]"``  a dataset in the data root (``dtradar_data.load``), e.g. ``cubicle/blueprint``.
``"synthetic/<variant>"``            a synthetic cubicle-sized 42 x 18 table (0.25 m cells, free-space line-of-sight
                                     radio features from :mod:`dtradar_data.pipeline.synthetic`) with desk-like
                                     obstacles; the
                                     ``dynamic`` variant adds a chair and two people, like the paper's dynamic twin.
``"synthetic-<nx>x<ny>/<variant>"``  the same generator at another size (tests use tiny ones).
``"synthetic-moving[-<nx>x<ny>]/<variant>"``  a *moving* twin (:func:`dtradar_data.pipeline.synthetic.
                                     synthetic_moving_dataset`): the same static obstacles plus three 1-cell movers
                                     walking back and forth along rows and columns, one snapshot per second, as many
                                     snapshots as the movers need to loop (6 at 12 x 8, 12 at 42 x 18).
"""

from __future__ import annotations

import re

import numpy as np

from dtradar_data import load, synthetic_dataset, synthetic_moving_dataset
from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DatasetNotFoundError, DtradarError, unknown_name
from dtradar_data.core.ids import VARIANTS

_SYNTH = re.compile(r"^synthetic(-moving)?(?:-(\d+)x(\d+))?$")


def is_synthetic(scene: str) -> bool:
    return bool(_SYNTH.match(scene))


def synthetic_blocked(nx: int, ny: int, variant: str = "blueprint") -> np.ndarray:
    """A deterministic obstacle layout ``bool[ny, nx]``: desk blocks in two rows, a table, chairs.

    At 42 x 18 it mimics the cubicle room (7 cubicles, a table, chairs); the ``dynamic`` variant adds obstacles
    on free cells (a chair, two people). Tiny grids (< 6 cells a side) get a single short wall.
    """
    if variant not in VARIANTS:
        raise unknown_name("variant", variant, VARIANTS)
    b = np.zeros((ny, nx), bool)
    if nx < 6 or ny < 6:
        if nx >= 3:
            b[: max(1, ny - 2), nx // 2] = True
    else:
        sx, sy = nx / 42.0, ny / 18.0

        def box(x0, y0, w, h):
            x0, y0 = int(round(x0 * sx)), int(round(y0 * sy))
            w, h = max(1, int(round(w * sx))), max(1, int(round(h * sy)))
            b[y0 : y0 + h, x0 : x0 + w] = True

        for k in range(4):  # lower row of cubicles (U-shaped: back + one side)
            box(3 + 9 * k, 2, 6, 1)
            box(3 + 9 * k, 3, 1, 3)
        for k in range(3):  # upper row
            box(7 + 10 * k, 12, 6, 1)
            box(12 + 10 * k, 9, 1, 3)
        box(36, 8, 3, 3)  # table
        for x, y in [(6, 7), (15, 7), (24, 7), (33, 14), (2, 13), (20, 15)]:  # chairs
            box(x, y, 1, 1)
        if variant == "dynamic":
            for x, y in [(10, 8), (28, 6), (18, 11), (3, 9)]:  # a chair, two people, a re-placed chair
                box(x, y, 1, 1)
    if variant == "dynamic" and (nx < 6 or ny < 6):
        b[ny - 1, 0] = True
    return b


def load_dataset(name: str) -> Dataset:
    """A dataset by name (see the module docstring): synthetic ones are generated, others come from the store."""
    scene, _, variant = name.partition("/")
    variant, _, revision = variant.partition("@")
    m = _SYNTH.match(scene)
    if m:
        nx, ny = (int(m.group(2)), int(m.group(3))) if m.group(2) else (42, 18)
        variant = variant or "blueprint"
        blocked = synthetic_blocked(nx, ny, variant)
        cell_m = 0.25
        tx = (nx * cell_m / 2, ny * cell_m / 2, 3.0)
        if m.group(1):
            return synthetic_moving_dataset(nx, ny, blocked=blocked, cell_m=cell_m, tx=tx, name=f"{scene}/{variant}")
        return synthetic_dataset(nx, ny, blocked, cell_m=cell_m, tx=tx, name=f"{scene}/{variant}")
    return load(f"{scene}/{variant}", revision or None)


def check_scenes(scenes, option: str, variant: str = "blueprint") -> None:
    """Every scene of ``scenes`` has its ``<scene>/<variant>`` twin here (synthetic ones always do): checked from the
    store's listing, before a job loads or trains anything. An unknown name is an :class:`UnknownNameError` with
    suggestions, a known but unbuilt twin a :class:`DatasetNotFoundError` saying how to build it; both name
    ``--<option>``."""
    from dtradar_data.store import list_datasets

    stored = [s for s in scenes if not is_synthetic(s)]
    listing = list_datasets() if stored else []
    entries = {e.name: e for e in listing}
    for scene in stored:
        entry = entries.get(f"{scene}/{variant}")
        if entry is not None and entry.built:
            continue
        flag = "--" + option.replace("_", "-")
        if entry is None and scene not in {e.scene for e in listing}:
            built = sorted({e.scene for e in listing if e.built and e.variant == variant} | {"synthetic"})
            raise unknown_name(f"scene ({flag})", scene, built)
        raise DatasetNotFoundError(
            f"{flag}: {scene}/{variant} is not built here",
            hint=f"build it first (make dataset SCENE={scene}), or leave {scene} out of {flag}",
        )


def dataset_exists(name: str) -> bool:
    """Whether :func:`load_dataset` would find ``name`` (always true for synthetic names)."""
    try:
        load_dataset(name)
        return True
    except DtradarError:  # not built, damaged or unknown: not usable here
        return False
