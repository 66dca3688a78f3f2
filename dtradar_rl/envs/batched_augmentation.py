"""Obstacle augmentation of the batched env: extra obstacles per robot and episode, and the BFS that keeps pairs
connected.

Obstacle augmentation (domain randomisation, off by default)
-----------------------------------------------------------
``aug_obstacles=k`` blocks, on every episode reset and independently per robot, ``k`` random extra obstacles on free
cells of the training twin: axis-aligned rectangles of 1 .. ``aug_obstacle_size`` cells a side (2 at 0.5 m cells:
the footprint of a chair or a standing person), never covering the robot's start or target. For that robot, until
its next reset, an extra-blocked cell behaves like a blocked cell of the table:

* a move into it is a **collision** (the robot stays, collision penalty);
* seen from a neighbouring cell (``neighbors`` preset), its 8 radio features read as missing (normalised value 0)
  and its has-radio flag as 0, exactly as a blocked neighbour in a ray-traced table; with a wider sensing radius
  (:mod:`dtradar_rl.task.observations`) its flags in the ring read 0 too, now and in the snapshot before (it stands
  there the whole episode).

What it does *not* simulate: in a real re-traced twin a new object also changes the radio features of the free
cells around it (new reflections, shadowing of the strongest path), the robot's own cell included. That needs a ray
tracer; here the other cells keep the blueprint's features.

Pairs and shaping stay consistent: after the obstacles are drawn a breadth-first search from the target runs on the
augmented grid (per robot, batched in torch), and the start is drawn uniformly among the cells still connected to
the target (explicit starts that end up cut off lose that robot's extra obstacles). The ``geodesic`` potential is
then either that per-robot distance (``aug_potential="replan"``, the default: a step along a shortest detour is
rewarded +1, as on the blueprint) or the blueprint's distance (``"blueprint"``: detours around an extra obstacle
look like steps away from the target and are rewarded -1 each; only the telescoping sum stays right). Note that
``replan`` rewards a detour that starts before the obstacle is visible to the robot, which its observation cannot
explain; ``blueprint`` rewards only what the map said.
With ``aug_obstacles=0`` nothing of this runs and the env is exactly the unaugmented one (same random streams).
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_data.core.errors import InvalidCoordinatesError, unknown_name
from dtradar_rl.task.observations import ObservationTable, ring_cells

#: How the geodesic potential treats augmented obstacles (see the module docstring).
AUG_POTENTIALS: tuple[str, ...] = ("replan", "blueprint")
#: Above this many (target, cell) entries the geodesic distance table keeps only a random pool of targets.
MAX_DISTANCE_TABLE = 32_000_000


class AugmentationMixin:
    """Obstacle augmentation of :class:`~dtradar_rl.envs.batched.BatchedNavEnv` (only allocated when on)."""

    @staticmethod
    def _check_augmentation(mdp, num_envs: int, aug_obstacles: int, aug_obstacle_size: int, aug_potential: str) -> None:
        """Refuse augmentation settings before anything is allocated."""
        if aug_obstacles < 0 or aug_obstacle_size < 1:
            raise InvalidCoordinatesError(
                f"aug_obstacles must be >= 0 and aug_obstacle_size >= 1, got {aug_obstacles} and {aug_obstacle_size}"
            )
        if aug_potential not in AUG_POTENTIALS:
            raise unknown_name("augmentation potential", aug_potential, AUG_POTENTIALS)
        if aug_obstacles and num_envs * mdp.num_cells > MAX_DISTANCE_TABLE:
            raise InvalidCoordinatesError(
                f"obstacle augmentation keeps a [num_envs, cells] mask and distance table: {num_envs} x "
                f"{mdp.num_cells} is over {MAX_DISTANCE_TABLE:,}",
                hint="use fewer robots (num_envs)",
            )

    def _init_augmentation(self, aug_obstacles: int, aug_obstacle_size: int, aug_potential: str) -> None:
        """Allocate the per-robot masks and distance tables (nothing when ``aug_obstacles`` is 0)."""
        mdp, obs_table, n, dev = self.mdp, self.obs_table, self.num_envs, self.device
        t = lambda a, dt: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=dev)  # noqa: E731
        self.aug_obstacles, self.aug_obstacle_size = int(aug_obstacles), int(aug_obstacle_size)
        self.aug_potential = aug_potential
        if self.aug_obstacles:
            self.free_cells = t(np.flatnonzero(mdp.free), torch.long)
            self.free_mask = t(mdp.free, torch.bool)
            #: ``bool[num_envs, cells]``: each robot's extra obstacles in its current episode.
            self.extra = torch.zeros((n, mdp.num_cells), dtype=torch.bool, device=dev)
            #: ``int32[num_envs, cells]``: BFS distance to each robot's target on its augmented grid (-1: cut off).
            self.adist = torch.full((n, mdp.num_cells), -1, dtype=torch.int32, device=dev)
            self._nbr_cols = self._neighbor_columns(obs_table)
            #: ``long[cells, K]``: the wider ring around each cell (off the grid: cell 0, whose flag there is 0 anyway)
            self._ring = t(ring_cells(mdp.nx, mdp.ny, obs_table.sense_radius).clip(min=0), torch.long)

    @staticmethod
    def _neighbor_columns(obs_table: ObservationTable) -> torch.Tensor | None:
        """``long[4, F+1]``: the cell-part columns (radio features + has-radio flag) of each neighbour, if observed."""
        names = obs_table.names
        acts = [nm.split(":")[0] for nm in names if nm.endswith(":has_radio")]  # X-, X+, Y-, Y+ (action order)
        if not acts:
            return None
        return torch.as_tensor(
            [[k for k, nm in enumerate(names) if nm.startswith(f"{a}:")] for a in acts], dtype=torch.long
        )

    def _draw_obstacles(self, k: int) -> torch.Tensor:
        """``bool[k, cells]``: ``aug_obstacles`` random rectangles (1 .. ``aug_obstacle_size`` a side) on free cells."""
        m, size, dev = self.aug_obstacles, self.aug_obstacle_size, self.device
        nx, ny = self.mdp.nx, self.mdp.ny
        seed = self.free_cells[torch.randint(self.free_cells.numel(), (k, m), generator=self.gen, device=dev)]
        sy, sx = seed // nx, seed % nx
        w = torch.randint(1, size + 1, (k, m), generator=self.gen, device=dev)
        h = torch.randint(1, size + 1, (k, m), generator=self.gen, device=dev)
        mask = torch.zeros((k, self.mdp.num_cells), dtype=torch.bool, device=dev)
        rows = torch.arange(k, device=dev)[:, None].expand(k, m)
        for dy in range(size):
            for dx in range(size):
                x, y = sx + dx, sy + dy
                ok = (dx < w) & (dy < h) & (x < nx) & (y < ny)
                mask[rows[ok], (y * nx + x)[ok]] = True
        return mask & self.free_mask

    def _bfs(self, targets: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
        """``int32[k, cells]`` breadth-first distances to ``targets`` on the grid with ``extra`` cells blocked too
        (-1: blocked or cut off). Frontier propagation on a zero-padded ``[k, ny+2, nx+2]`` grid with shifted views:
        no gathers, a few tensor ops per step, so a batch of resets costs ~2-3 ms on the 42 x 18 cubicle."""
        k, (h, w) = targets.numel(), self.mdp.blocked.shape
        rows = torch.arange(k, device=self.device)
        unvisited = torch.zeros((k, h + 2, w + 2), dtype=torch.bool, device=self.device)
        open_ = unvisited[:, 1:-1, 1:-1]  # passable cells not reached yet
        open_.copy_((self.free_mask[None] & ~extra).view(k, h, w))
        frontier = torch.zeros_like(unvisited)
        ty, tx = targets // w, targets % w
        frontier[rows, ty + 1, tx + 1] = True
        open_[rows, ty, tx] = False
        waited = torch.zeros((k, h, w), dtype=torch.int32, device=self.device)  # steps each cell stayed unreached
        step = 0
        while True:
            step += 1
            new = (
                frontier[:, :-2, 1:-1] | frontier[:, 2:, 1:-1] | frontier[:, 1:-1, :-2] | frontier[:, 1:-1, 2:]
            ) & open_
            open_ ^= new
            frontier[:, 1:-1, 1:-1] = new
            waited += open_
            if step % 4 == 0 and not bool(new.any()):  # a few idle steps past the end change nothing
                break
        dist = (waited + 1).view(k, -1)
        dist[open_.reshape(k, -1) | ~self.free_mask[None] | extra] = -1
        dist[rows, targets] = 0
        return dist

    def _augment(self, idx: torch.Tensor, tgt: torch.Tensor, starts: torch.Tensor | None) -> torch.Tensor:
        """Draw new extra obstacles for robots ``idx``; returns their starts (drawn here unless given)."""
        k = idx.numel()
        rows = torch.arange(k, device=self.device)
        extra = self._draw_obstacles(k)
        extra[rows, tgt] = False
        if starts is not None:
            extra[rows, starts] = False
        dist = self._bfs(tgt, extra)
        reachable = dist > 0
        # Obstacles that cut the start (or every cell) off the target are dropped for that robot.
        cut = ~reachable.any(1) if starts is None else ~reachable[rows, starts]
        if bool(cut.any()):
            extra[cut] = False
            dist[cut] = self._bfs(tgt[cut], extra[cut])
            reachable = dist > 0
        if starts is None:
            starts = torch.multinomial(reachable.float(), 1, generator=self.gen).squeeze(1)
        self.extra[idx], self.adist[idx] = extra, dist
        return starts
