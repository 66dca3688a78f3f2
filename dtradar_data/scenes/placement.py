"""Where a deployment would put its transmitters: greedy line-of-sight coverage of a twin's free cells.

A radio planner places access points or small cells so that every street (or room) sees one, and the cheap model of
"sees" is line of sight on the floor plan: a cell covers another when the straight segment between their centres
crosses no blocked cell, within a range. :func:`place_sites` picks sites greedily, each the free cell that sees the
most cells no site sees yet (ties: the lowest cell index, so the result is deterministic), until a share of the free
cells is covered or ``max_sites`` are placed. Greedy maximum coverage is within ``1 - 1/e`` of the best set of that
size, and it is what planning tools do first.

Line of sight on the plan is a lower bound on what the ray tracer finds: reflections and diffraction reach around
corners. It ignores heights (a transmitter above the roofs sees more); sites are for transmitters below the
roofline, on lamp posts or façades. Used to place the transmitters of ``sionna:munich-10tx`` and
``dallas-3tx-q3``; ``python -m dtradar_data place sionna:munich`` prints sites (``dtradar_data.cli.PlaceCmd``), and
``--heard-in`` a built twin places the next ones where its trace found no path (a second round, measured rather than
modelled).
"""

from __future__ import annotations

import numpy as np

from dtradar_data.core.errors import InvalidSettingError

__all__ = ["place_sites", "visibility"]


def visibility(blocked: np.ndarray, sites: np.ndarray, *, range_cells: float, rays: int = 720) -> np.ndarray:
    """``bool[len(sites), H*W]``: the cells each site (flat cell index) sees, by marching ``rays`` straight rays
    out of its centre in steps of a quarter cell until a blocked cell or the grid's edge or ``range_cells``."""
    h, w = blocked.shape
    angles = np.linspace(0.0, 2 * np.pi, rays, endpoint=False)
    steps = np.arange(0.0, range_cells, 0.25)
    dx, dy = np.cos(angles)[:, None] * steps, np.sin(angles)[:, None] * steps  # [rays, steps]
    out = np.zeros((len(sites), h * w), bool)
    for n, site in enumerate(np.asarray(sites, np.int64)):
        sy, sx = divmod(int(site), w)
        x = np.floor(sx + 0.5 + dx).astype(np.int64)
        y = np.floor(sy + 0.5 + dy).astype(np.int64)
        inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        cell = np.where(inside, y * w + x, 0)
        open_ = inside & ~blocked.ravel()[cell]
        seen = np.cumprod(open_, axis=1).astype(bool)  # a ray stops at its first blocked or outside sample
        out[n, cell[seen]] = True
    return out


def _clear_cells(blocked: np.ndarray, clearance_cells: int) -> np.ndarray:
    """The flat indices of the cells whose every cell within ``clearance_cells`` (a square; outside the grid counts
    as blocked) is free; :class:`InvalidSettingError` naming ``--clearance-cells`` and the widest the plan allows
    when there is none."""
    if clearance_cells < 0:
        raise InvalidSettingError(
            f"--clearance-cells {clearance_cells} must be >= 0", hint="0 allows a site against a wall"
        )
    h, w = blocked.shape
    near = blocked.copy()
    for widest in range(clearance_cells):  # grow the blocked cells by one cell (a 3 x 3 square) at a time
        if near.all():
            break
        padded = np.pad(near, 1, constant_values=True)
        for oy in range(3):
            for ox in range(3):
                near |= padded[oy : oy + h, ox : ox + w]
        if near.all():
            raise InvalidSettingError(
                f"--clearance-cells {clearance_cells}: no free cell has {clearance_cells} free cells all around it "
                "on this plan",
                hint=f"lower it: at most --clearance-cells {widest} here (0 allows a site against a wall)",
            )
    if near.all():
        raise InvalidSettingError(
            "the plan has no free cell to place a transmitter on", hint="check the scene's grid and its objects"
        )
    return np.flatnonzero(~near.ravel())


def place_sites(
    blocked: np.ndarray,
    *,
    range_cells: float,
    coverage: float = 0.99,
    max_sites: int = 16,
    clearance_cells: int = 1,
    start: tuple[int, ...] = (),
    covered: np.ndarray | None = None,
) -> tuple[list[int], float]:
    """Greedy sites (flat cell indices, in the order picked) and the share of free cells they see; ``start`` are
    sites already there (an existing transmitter), kept first; ``covered`` (``bool[H, W]``) the cells reached some
    other way (a traced twin's cells with a path: the next sites go where the ray tracer found none).

    Candidates are the free cells whose every cell within ``clearance_cells`` (a square) is free too, so that a
    transmitter stands in the open, not against a wall."""
    blocked = np.asarray(blocked, bool)
    h, w = blocked.shape
    free = ~blocked.ravel()
    candidates = _clear_cells(blocked, clearance_cells)
    seen = visibility(blocked, candidates, range_cells=range_cells) & free[None, :]
    covered = np.zeros(h * w, bool) if covered is None else np.asarray(covered, bool).ravel().copy()
    sites: list[int] = [int(c) for c in start]
    if sites:
        covered |= (visibility(blocked, np.array(sites), range_cells=range_cells) & free[None, :]).any(axis=0)
    total = int(free.sum())
    while len(sites) < max_sites and covered.sum() < coverage * total:
        gain = (seen & ~covered[None, :]).sum(axis=1)
        best = int(np.argmax(gain))  # argmax takes the first of equal gains: deterministic
        if gain[best] == 0:
            break
        sites.append(int(candidates[best]))
        covered |= seen[best]
    return sites, float(covered.sum() / total)
