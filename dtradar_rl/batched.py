"""A batched torch environment: thousands of robots stepped at once by table lookup, on CPU or CUDA.

Same MDP, rewards and observations as the gymnasium env (:class:`dtradar_rl.envs.DtradarNavEnv`); a test checks
they agree step for step. There is no automatic reset: :meth:`BatchedNavEnv.step` returns the next observation of
every robot (terminal ones included, which is what a replay buffer needs) and the caller resets finished robots with
:meth:`BatchedNavEnv.reset_where`.

    env = BatchedNavEnv.from_dataset(ds, num_envs=1024, obs="goal", reward="geodesic", seed=0)
    obs = env.reset()
    next_obs, reward, terminated, truncated, info = env.step(actions)
    env.reset_where(terminated | truncated); obs = env.observe()
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_data.dataset import Dataset
from dtradar_data.errors import InvalidCoordinatesError

from .mdp import GridMDP, NoConnectedPairError, check_reward, potential_kind, reward_fn
from .observations import Normalizer, ObservationTable, build_observations, check_preset

#: Above this many (target, cell) entries the geodesic distance table keeps only a random pool of targets.
MAX_DISTANCE_TABLE = 32_000_000


class BatchedNavEnv:
    """``num_envs`` independent navigation episodes on one grid, stepped together as torch tensors."""

    def __init__(self, mdp: GridMDP, obs_table: ObservationTable, num_envs: int, *, reward: str = "geodesic",
                 max_steps: int | None = None, device: str | torch.device = "cpu", seed: int = 0,
                 target_pool: int | None = None):
        if num_envs < 1:
            raise InvalidCoordinatesError(f"num_envs must be >= 1, got {num_envs}")
        self.mdp, self.obs_table, self.num_envs = mdp, obs_table, int(num_envs)
        self.reward_name = check_reward(reward)
        self.potential = potential_kind(reward)
        self.max_steps = int(max_steps or mdp.max_steps)
        self.device = torch.device(device)
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(int(seed))
        dev = self.device
        t = lambda a, dt: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=dev)  # noqa: E731
        self.next_cell = t(mdp.next_cell, torch.long)
        self.collides = t(mdp.collides, torch.bool)
        self.cell_part = t(obs_table.cell_part, torch.float32)
        self.target_part = t(obs_table.target_part, torch.float32)
        iy, ix = np.divmod(np.arange(mdp.num_cells), mdp.nx)
        self.ix, self.iy = t(ix, torch.float32), t(iy, torch.float32)

        # Pair sampling: target uniform over the pool, start uniform over the rest of the target's component.
        cells = mdp.pair_cells()
        if cells.size == 0:
            raise NoConnectedPairError(f"{mdp.name}: no two free cells are connected")
        order = np.argsort(mdp.component[cells], kind="stable")
        members = cells[order]
        comp = mdp.component[members]
        ncomp = int(mdp.component.max()) + 1
        size = np.bincount(comp, minlength=ncomp)
        first = np.concatenate([[0], np.cumsum(size)[:-1]])
        rank = np.zeros(mdp.num_cells, np.int64)
        rank[members] = np.arange(members.size) - first[comp]
        self.members, self.comp_first = t(members, torch.long), t(first, torch.long)
        self.comp_size = t(size, torch.long)
        self.component, self.rank = t(mdp.component, torch.long), t(rank, torch.long)

        rng = np.random.default_rng(seed)
        if target_pool is None and cells.size * mdp.num_cells > MAX_DISTANCE_TABLE and self.potential == "geodesic":
            target_pool = max(1, MAX_DISTANCE_TABLE // mdp.num_cells)
        pool = cells if not target_pool or target_pool >= cells.size else np.sort(
            rng.choice(cells, target_pool, replace=False))
        self.pool = t(pool, torch.long)
        self._pool_pos = {int(c): k for k, c in enumerate(pool)}
        self.dist = (t(mdp.bfs_distances_many(pool), torch.int32) if self.potential == "geodesic"
                     else torch.zeros((pool.size, 0), dtype=torch.int32, device=dev))

        n = self.num_envs
        self.cell = torch.zeros(n, dtype=torch.long, device=dev)
        self.target = torch.zeros(n, dtype=torch.long, device=dev)
        self.tpool = torch.zeros(n, dtype=torch.long, device=dev)
        self.steps = torch.zeros(n, dtype=torch.long, device=dev)

    @classmethod
    def from_dataset(cls, ds: Dataset, num_envs: int, *, obs: str = "goal", normalizer: Normalizer | None = None,
                     **kwargs) -> BatchedNavEnv:
        """Build from a dataset; ``normalizer`` defaults to statistics of ``ds`` itself."""
        check_preset(obs)
        normalizer = normalizer or Normalizer.fit(ds)
        return cls(GridMDP.from_dataset(ds), build_observations(ds, obs, normalizer), num_envs, **kwargs)

    @property
    def obs_dim(self) -> int:
        return self.obs_table.dim

    # -- episodes ------------------------------------------------------------------------------------------------
    def reset(self) -> torch.Tensor:
        self.reset_where(torch.ones(self.num_envs, dtype=torch.bool, device=self.device))
        return self.observe()

    def reset_where(self, mask: torch.Tensor, starts=None, targets=None) -> None:
        """Start new episodes where ``mask`` is true: random connected pairs, or the given cell indices."""
        idx = torch.nonzero(mask.to(self.device), as_tuple=True)[0]
        k = idx.numel()
        if k == 0:
            return
        if targets is None:
            tp = torch.randint(self.pool.numel(), (k,), generator=self.gen, device=self.device)
            tgt = self.pool[tp]
        else:
            tgt = torch.as_tensor(targets, dtype=torch.long, device=self.device).reshape(k)
            tp = self._pool_rows(tgt)
        if starts is None:
            c = self.component[tgt]
            j = (torch.rand(k, generator=self.gen, device=self.device) * (self.comp_size[c] - 1)).long()
            j = j + (j >= self.rank[tgt]).long()
            st = self.members[self.comp_first[c] + j]
        else:
            st = torch.as_tensor(starts, dtype=torch.long, device=self.device).reshape(k)
        self.cell[idx], self.target[idx], self.tpool[idx] = st, tgt, tp
        self.steps[idx] = 0

    def _pool_rows(self, targets: torch.Tensor) -> torch.Tensor:
        """Rows of the distance table for explicit targets, computing and appending missing ones."""
        cells = [int(c) for c in targets.tolist()]
        missing = sorted({c for c in cells if c not in self._pool_pos})
        if missing:
            for c in missing:
                if self.mdp.blocked.ravel()[c]:
                    raise InvalidCoordinatesError(f"target cell {self.mdp.xy(c)} is blocked")
                self._pool_pos[c] = len(self._pool_pos)
            extra = torch.as_tensor(missing, dtype=torch.long, device=self.device)
            self.pool = torch.cat([self.pool, extra])
            if self.potential == "geodesic":
                d = torch.as_tensor(self.mdp.bfs_distances_many(np.array(missing)), dtype=torch.int32,
                                    device=self.device)
                self.dist = torch.cat([self.dist, d])
            else:
                self.dist = torch.cat([self.dist, torch.zeros((len(missing), 0), dtype=torch.int32,
                                                              device=self.device)])
        return torch.as_tensor([self._pool_pos[c] for c in cells], dtype=torch.long, device=self.device)

    def observe(self) -> torch.Tensor:
        """``float32[num_envs, obs_dim]`` observations of the current cells."""
        return torch.cat([self.cell_part[self.cell], self.target_part[self.target]], 1)

    def _potential(self, cell: torch.Tensor) -> torch.Tensor:
        if self.potential == "geodesic":
            return self.dist[self.tpool, cell].float()
        dx, dy = self.ix[self.target] - self.ix[cell], self.iy[self.target] - self.iy[cell]
        return torch.sqrt(dx * dx + dy * dy)

    def step(self, actions: torch.Tensor):
        """Move every robot; returns ``(next_obs, reward, terminated, truncated, info)`` (no auto-reset).

        ``info``: ``collision`` (bool[N]), ``is_success`` (= terminated), ``steps`` (steps taken this episode).
        """
        a = actions.to(self.device, torch.long)
        cell = self.cell
        nxt = self.next_cell[cell, a]
        collision = self.collides[cell, a]
        reached = nxt == self.target
        dx, dy = self.ix[self.target] - self.ix[nxt], self.iy[self.target] - self.iy[nxt]
        if self.potential:
            pb, pa = self._potential(cell), self._potential(nxt)
        else:
            pb = pa = torch.zeros((), device=self.device)
        reward = reward_fn(self.reward_name, d2_after=dx * dx + dy * dy, pot_before=pb, pot_after=pa,
                           collision=collision.float(), reached=reached.float(), diag2=self.mdp.diag2).float()
        self.cell = nxt
        self.steps += 1
        terminated = reached
        truncated = (self.steps >= self.max_steps) & ~terminated
        info = {"collision": collision, "is_success": reached, "steps": self.steps.clone()}
        return self.observe(), reward, terminated, truncated, info
