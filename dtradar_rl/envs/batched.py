"""A batched torch environment: thousands of robots stepped at once by table lookup, on CPU or CUDA.

Same MDP, rewards and observations as the gymnasium env (:class:`dtradar_rl.envs.nav_env.DtradarNavEnv`); a test checks
they agree step for step. There is no automatic reset: :meth:`BatchedNavEnv.step` returns the next observation of
every robot (terminal ones included, which is what a replay buffer needs) and the caller resets finished robots with
:meth:`BatchedNavEnv.reset_where`.

    env = BatchedNavEnv.from_dataset(ds, num_envs=1024, obs="goal", reward="geodesic", seed=0)
    obs = env.reset()
    next_obs, reward, terminated, truncated, info = env.step(actions)
    env.reset_where(terminated | truncated); obs = env.observe()

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

Moving twins
------------
On a moving twin (:class:`~dtradar_rl.task.grid_mdp.MovingGridMDP`; the rules are in :mod:`dtradar_rl.task.grid_mdp`)
every robot has its own snapshot ``t`` (``env.t``): an episode starts at ``t0`` (``reset_where(..., t0=...)``, else
drawn uniformly among the snapshots in which the start cell is free) and each step advances it by one, mod ``T``.
A step reads the blocked masks of this snapshot and the next, and the observation of the robot's snapshot, from
``[T, cells]`` tables (row ``t * cells + cell``); ``info`` adds ``mover_collision``, ``mover_hit`` and ``t``. Random
pairs are connected on the static map; whether the movers leave the target reachable in time is not checked here (the
evaluation's pairs are, :meth:`~dtradar_rl.task.grid_mdp.MovingGridMDP.sample_episodes`). The ``geodesic`` shaping
and :meth:`BatchedNavEnv.shortest_moves` use the static map's breadth-first distance (movers ignored; still a
potential, so the optimum is unchanged). On a static twin none of this runs: the step is the one above, op for op.

The fast path
-------------
At 4 096 robots a step has ~200 us for 20 M steps/s, and a torch op on CPU costs a few us of dispatch whatever its
size, so on a static twin without obstacle augmentation (the common case; ``fast_path=True``, the default) the env
reads precomputed tables instead of evaluating the rules op by op:

* ``step``: one flat index ``key = 4 * cell + action`` and three gathers: the next cell and the collision of
  ``(cell, action)``, and the reward of ``(target, cell, action)`` from a ``float32[pool, cells, 4]`` table that
  the general step's own reward code (:meth:`BatchedNavEnv._reward`) computed for every entry, so it is the same
  float32 value bit for bit (every reward; cubicle: 592 targets x 756 cells x 4 = 1.8 M entries, 7 MB, built in
  ~50 ms);
* ``observe``: one row gather from ``[cell_part | 0]`` and the target's columns written into it (no ``cat``);
* ``reset_where`` (random pairs): the same two draws (a pool row, then ``u`` in [0, 1)) from the same generator,
  and the start read from a ``[pool, largest component]`` table of ``members[first + j + (j >= rank)]``.

Everything else (moving twins, augmentation, explicit cells, a table over :data:`FAST_TABLE_MAX` entries, actions
outside 0..3) takes the general path, which ``fast_path=False`` forces; a test checks that both give the same
trajectories bit for bit (observations, rewards, terminations, info, state, random streams). Measured figures are in
:meth:`BatchedNavEnv._step_fast`.
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidCoordinatesError, unknown_name
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP, NoConnectedPairError, check_max_steps
from dtradar_rl.task.noise import ERRORS, NOISE_SEED_OFFSET, NoiseModel, RadioNoise, noise_model
from dtradar_rl.task.observations import (
    Normalizer,
    ObservationTable,
    build_observations,
    check_preset,
    ring_cells,
)
from dtradar_rl.task.rewards import check_reward, potential_kind, reward_fn

#: Above this many (target, cell) entries the geodesic distance table keeps only a random pool of targets.
MAX_DISTANCE_TABLE = 32_000_000
#: How the geodesic potential treats augmented obstacles (see the module docstring).
AUG_POTENTIALS: tuple[str, ...] = ("replan", "blueprint")
#: Most entries of a fast-path table (the rewards: pool targets x cells x 4 actions, float32, 32 MB; the random
#: starts: pool targets x largest component); above it the env keeps the general path (see the module docstring).
FAST_TABLE_MAX = 8_000_000


class BatchedNavEnv:
    """``num_envs`` independent navigation episodes on one grid, stepped together as torch tensors."""

    def __init__(
        self,
        mdp: GridMDP,
        obs_table: ObservationTable,
        num_envs: int,
        *,
        reward: str = "geodesic",
        max_steps: int | None = None,
        device: str | torch.device = "cpu",
        seed: int = 0,
        target_pool: int | None = None,
        aug_obstacles: int = 0,
        aug_obstacle_size: int = 1,
        aug_potential: str = "replan",
        noise: str | NoiseModel = "none",
        fast_path: bool = True,
    ):
        if num_envs < 1:
            raise InvalidCoordinatesError(f"num_envs must be >= 1, got {num_envs}")
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
        self.mdp, self.obs_table, self.num_envs = mdp, obs_table, int(num_envs)
        #: a moving twin (snapshots in time); decided here, once: a static twin's step is unchanged
        self.moving = isinstance(mdp, MovingGridMDP)
        self.snapshots = mdp.snapshots if self.moving else 1
        if obs_table.snapshots != self.snapshots:
            raise InvalidCoordinatesError(
                f"the observation table has {obs_table.snapshots} snapshot(s), the MDP {self.snapshots}",
                hint="build both from the same dataset",
            )
        self.reward_name = check_reward(reward)
        self.potential = potential_kind(reward)
        self.max_steps = check_max_steps(max_steps) or mdp.max_steps
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
        pool = (
            cells
            if not target_pool or target_pool >= cells.size
            else np.sort(rng.choice(cells, target_pool, replace=False))
        )
        self.pool = t(pool, torch.long)
        self._pool_pos = {int(c): k for k, c in enumerate(pool)}
        self.dist = (
            t(mdp.bfs_distances_many(pool), torch.int32)
            if self.potential == "geodesic"
            else torch.zeros((pool.size, 0), dtype=torch.int32, device=dev)
        )

        n = self.num_envs
        self.cell = torch.zeros(n, dtype=torch.long, device=dev)
        self.target = torch.zeros(n, dtype=torch.long, device=dev)
        self.tpool = torch.zeros(n, dtype=torch.long, device=dev)
        self.steps = torch.zeros(n, dtype=torch.long, device=dev)
        if self.moving:
            #: ``long[num_envs]``: each robot's snapshot
            self.t = torch.zeros(n, dtype=torch.long, device=dev)
            #: ``bool[T * cells]``: blocked at snapshot t (static obstacle or mover), row ``t * cells + cell``
            self.covered = t(mdp.covered.ravel(), torch.bool)
            self.t_next = t((np.arange(self.snapshots) + 1) % self.snapshots, torch.long)

        # Obstacle augmentation (only allocated when on; see the module docstring).
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

        # Measurement noise (see dtradar_rl.task.noise): its own generator, so "none" leaves every draw unchanged.
        model = noise_model(noise)
        self.noise = None if model.is_zero else RadioNoise(model, obs_table, obs_table.normalizer, dev)
        self.noise_gen = torch.Generator(device=dev)
        self.noise_gen.manual_seed(int(seed) + NOISE_SEED_OFFSET)
        if self.noise is not None:  # drawn at every reset and step; nothing is observed before the first reset
            self.errors = torch.zeros((n, self.noise.groups, len(ERRORS)), dtype=torch.float64, device=dev)

        #: use the fast path where it applies (module docstring); False keeps the general one (tests, the bench)
        self.fast_path = bool(fast_path)
        self._build_fast()

    def _draw_errors(self, idx: torch.Tensor | None = None) -> None:
        """A new measurement for robots ``idx`` (default all): fresh noise errors."""
        if self.noise is None:
            return
        if idx is None:
            self.errors = self.noise.draw(self.num_envs, self.noise_gen)
        else:
            self.errors[idx] = self.noise.draw(idx.numel(), self.noise_gen)

    # -- the fast path ----------------------------------------------------------------------------------------------
    def _build_fast(self) -> None:
        """Decide which fast paths apply and build their tables (again whenever the target pool grows)."""
        plain = self.fast_path and not self.moving and not self.aug_obstacles
        n, p, dev = self.mdp.num_cells, self.pool.numel(), self.device
        #: ``observe`` is one row gather from ``_obs_wide`` (``[cell_part | 0]``) and the target's columns
        self._fast_obs = plain and self.noise is None
        if self._fast_obs:
            dc, dt = self.cell_part.shape[1], self.target_part.shape[1]
            self._obs_wide = torch.zeros((n, dc + dt), dtype=torch.float32, device=dev)
            self._obs_wide[:, :dc] = self.cell_part
            # The target's two float32 columns as one int64 (the same bytes): written as one strided column, 8x
            # faster than a [N, 2] slice (whose 2-element inner loop costs ~50 us at 4 096 robots).
            pairs = dt == 2 and dc % 2 == 0 and dev.type == "cpu"  # (a CPU kernel's cost; elsewhere the slice)
            self._obs_target = self.target_part.view(torch.int64).reshape(-1) if pairs else None
        #: ``step`` reads the next cell, the collision and the reward with one flat index ``(target, cell, action)``
        self._fast_step = plain and p * n * 4 <= FAST_TABLE_MAX
        if self._fast_step:
            #: ``long[cells, 4]``: ``4 * cell + action``, indexed like ``next_cell`` (off a CPU: no host sync)
            self._keys = torch.arange(n * 4, device=dev).view(n, 4)
            self._next_flat = self.next_cell.reshape(-1).contiguous()
            self._collides_flat = self.collides.reshape(-1).contiguous()
            self._rtab = self._reward_table().reshape(-1)
        # random starts: ``members[first + j + (j >= rank)]`` of the target's component, tabulated per (pool row, j)
        span = self.comp_size[self.component[self.pool].clamp(min=0)] - 1
        width = max(1, int(span.max()))
        #: ``reset_where`` without explicit cells draws ``j`` as the general path does and reads the start
        self._fast_reset = plain and bool((span >= 1).all()) and p * width <= FAST_TABLE_MAX
        if self._fast_reset:
            j = torch.arange(width, device=dev)[None]
            c = self.component[self.pool][:, None]
            at = self.comp_first[c] + j + (j >= self.rank[self.pool][:, None]).long()
            valid = j < span[:, None]  # j = floor(u * span) < span for every u in [0, 1) (float32 included)
            self._starts = torch.where(valid, self.members[at.clamp(max=self.members.numel() - 1)], 0).reshape(-1)
            self._span, self._span_width = span.float(), width

    def _reward_table(self) -> torch.Tensor:
        """``float32[pool, cells, 4]``: the reward of each action from each cell towards each pool target, computed by
        the general step's own code (:meth:`_reward`, broadcasting ``[targets, 1, 1]`` against ``[1, cells, 4]``), so
        a lookup equals it bit for bit (the same float32 operations, elementwise). In blocks of ~1 M entries."""
        n, p, dev = self.mdp.num_cells, self.pool.numel(), self.device
        cell = torch.arange(n, device=dev)[None, :, None]
        nxt, coll = self.next_cell[None], self.collides[None]  # [1, cells, 4]
        out = torch.empty((p, n, 4), dtype=torch.float32, device=dev)
        block = max(1, (1 << 20) // (n * 4))
        for r0 in range(0, p, block):
            tpool = torch.arange(r0, min(p, r0 + block), device=dev)[:, None, None]
            target = self.pool[tpool]
            out[r0 : r0 + tpool.shape[0]] = self._reward(cell, nxt, target, tpool, coll, nxt == target)
        return out

    @staticmethod
    def _valid_actions(a: torch.Tensor) -> bool:
        """All of ``a`` in 0..3 (else the general step: it wraps -4..-1 and raises on the rest, as it always did)."""
        lo, hi = torch.aminmax(a)
        return 0 <= int(lo) and int(hi) <= 3

    def _step_fast(self, a: torch.Tensor):
        """:meth:`step` on a static twin without augmentation: three gathers from the fast tables.

        Measured with ``bench/bench_rl.py --env-only --threads 1`` (cubicle/blueprint, neighbors, geodesic; step +
        ``reset_where(te | tr)`` + ``observe()``; medians of 5 interleaved rounds) on the 2-core AMD EPYC shared with
        other jobs (1-min load 2.8-3.3), env steps/s; "before": the env as it was (advanced indexing everywhere),
        interleaved with the other two in a run of its own (load 2.5; actions drawn per step):

        ======  ===========  ============  ========  ==============================
        robots  fast path    general path  before    fast path, 2 torch threads
        ======  ===========  ============  ========  ==============================
        1       16.6 K       7.7 K         7 K       14.7 K
        256     2.07 M       1.24 M        1.07 M    2.30 M
        4 096   13.8 M       5.24 M        3.30 M    0.26 M (threads wait on a busy core)
        ======  ===========  ============  ========  ==============================

        At a load of 1.7 the fast path did 15.0 M steps/s at 4 096 robots.

        Per step at 4 096 robots: 37 torch ops instead of 56 (step 18 / 31, reset_where 14 / 22, observe 5 / 3),
        none of them advanced indexing: ``cell_part[cell]`` alone took 228 us where ``index_select`` takes 31 us, and
        ``next_cell[cell, a]`` 25 us where ``4 * cell + a`` and a flat ``index_select`` take 12 us. What is left:
        the two 786 KB observations (step's and observe's, ~31 us each: memory copies), ~25 small ops on 4 096
        elements (3-6 us each) and the robots' resets. ``torch.compile`` of this step (inductor, static shapes) took
        28 s to compile and ran it 2x slower (275 vs 132 us), so it is not used. Two torch threads collapse at 4 096
        robots whenever another process holds a core (the threads wait on each other): callers pick 1 for the env.
        int32 instead of int64 indices: no faster for ``index_select`` (6.6 vs 7.0 us), and the state stays long."""
        if a.device.type == "cpu":  # checked in step: 0 <= a <= 3
            key = torch.add(a, self.cell, alpha=4)  # (cell, action) row-major; 2x faster than _keys[cell, a]
        else:  # the general step's indexing (negative actions wrap, others fail), without a host sync
            key = self._keys[self.cell, a]
        nxt = self._next_flat.index_select(0, key)
        collision = self._collides_flat.index_select(0, key)
        reward = self._rtab.index_select(0, key.add_(self.tpool, alpha=4 * self.mdp.num_cells))
        reached = torch.eq(nxt, self.target)
        self.cell = nxt
        self.steps += 1
        self._draw_errors()
        truncated = torch.gt(self.steps >= self.max_steps, reached)  # bools: a > b is a & ~b
        info = {"collision": collision, "is_success": reached, "steps": self.steps.clone()}
        return self.observe(), reward, reached, truncated, info

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

    @property
    def state_keys(self) -> tuple[str, ...]:
        """Attributes that hold the episodes' state (what a training checkpoint saves to resume exactly)."""
        return (
            ("cell", "target", "tpool", "steps")
            + (("t",) if self.moving else ())
            + (("extra", "adist") if self.aug_obstacles else ())
            + (("errors",) if self.noise is not None else ())
        )

    @classmethod
    def from_dataset(
        cls,
        ds: Dataset,
        num_envs: int,
        *,
        obs: str = "goal",
        normalizer: Normalizer | None = None,
        sense_radius: int = 1,
        **kwargs,
    ) -> BatchedNavEnv:
        """Build from a dataset; ``normalizer`` defaults to statistics of ``ds`` itself; ``sense_radius`` widens the
        ``neighbors`` observation (:func:`~dtradar_rl.task.observations.build_observations`)."""
        check_preset(obs)
        normalizer = normalizer or Normalizer.fit(ds)
        table = build_observations(ds, obs, normalizer, sense_radius)
        return cls(GridMDP.from_dataset(ds), table, num_envs, **kwargs)

    @property
    def obs_dim(self) -> int:
        return self.obs_table.dim

    # -- episodes ------------------------------------------------------------------------------------------------
    def reset(self) -> torch.Tensor:
        self.reset_where(torch.ones(self.num_envs, dtype=torch.bool, device=self.device))
        return self.observe()

    def reset_where(self, mask: torch.Tensor, starts=None, targets=None, t0=None) -> None:
        """Start new episodes where ``mask`` is true: random connected pairs, or the given cell indices.

        ``t0``: the start snapshot of a moving twin, one int for all or one per robot reset (0 .. T-1; a static twin
        has one snapshot, 0); the start must be free then. Default: drawn per robot among the snapshots in which its
        start is free (a static twin draws nothing)."""
        idx = torch.nonzero(mask.to(self.device), as_tuple=True)[0]
        k = idx.numel()
        if k == 0:
            return
        if self._fast_reset and starts is None and targets is None and t0 is None:
            # the general path's draws (a pool row, then u in [0, 1) for the start), read from the start table
            tp = torch.randint(self.pool.numel(), (k,), generator=self.gen, device=self.device)
            j = torch.rand(k, generator=self.gen, device=self.device).mul_(self._span.index_select(0, tp)).long()
            self.cell.index_copy_(0, idx, self._starts.index_select(0, j.add_(tp, alpha=self._span_width)))
            self.target.index_copy_(0, idx, self.pool.index_select(0, tp))
            self.tpool.index_copy_(0, idx, tp)
            self.steps.index_fill_(0, idx, 0)
            self._draw_errors(idx)
            return
        if starts is not None and targets is None:
            raise InvalidCoordinatesError(
                "reset_where got starts without targets", hint="pass both (cell indices), or targets alone"
            )
        t0 = None if t0 is None else self._snapshot_arg(t0, k)
        if targets is None:
            tp = torch.randint(self.pool.numel(), (k,), generator=self.gen, device=self.device)
            tgt = self.pool[tp]
        else:
            tgt = self._cells("targets", targets, k)
            tp = self._pool_rows(tgt)
        st = None if starts is None else self._cells("starts", starts, k)
        if st is not None and not bool(((st != tgt) & (self.component[st] == self.component[tgt])).all()):
            raise InvalidCoordinatesError(
                "reset_where: a start is its target's cell, or cannot reach it", hint="pass connected, distinct cells"
            )
        if self.aug_obstacles:
            st = self._augment(idx, tgt, st)
        elif st is None:
            c = self.component[tgt]
            j = (torch.rand(k, generator=self.gen, device=self.device) * (self.comp_size[c] - 1)).long()
            j = j + (j >= self.rank[tgt]).long()
            st = self.members[self.comp_first[c] + j]
        if self.moving:
            self.t[idx] = self._start_snapshots(idx, st, tgt, t0, explicit=starts is not None)
        self.cell[idx], self.target[idx], self.tpool[idx] = st, tgt, tp
        self.steps[idx] = 0
        self._draw_errors(idx)

    def _snapshot_arg(self, t0, k: int) -> torch.Tensor:
        """``t0`` (one int, or ``k``) as a long tensor of snapshots, or :class:`InvalidCoordinatesError`."""
        try:
            t = torch.as_tensor(t0, device=self.device)
        except (TypeError, ValueError, RuntimeError) as e:
            raise InvalidCoordinatesError(f"reset_where t0 is {t0!r}, not snapshot indices", hint="pass ints") from e
        if t.dtype.is_floating_point or t.dtype == torch.bool or t.is_complex():
            raise InvalidCoordinatesError(
                f"reset_where t0 must be integer snapshot indices, got {t.dtype}", hint=f"pass an int or {k} ints"
            )
        if t.numel() not in (1, k) or t.dim() > 1:
            raise InvalidCoordinatesError(
                f"reset_where t0: {t.numel()} snapshots for {k} robots", hint=f"pass one int, or one per robot ({k})"
            )
        t = t.reshape(-1).long().expand(k).clone()
        if not bool(((t >= 0) & (t < self.snapshots)).all()):
            raise InvalidCoordinatesError(
                f"reset_where t0: a snapshot is outside 0..{self.snapshots - 1}",
                hint="a static twin has one snapshot (0)"
                if not self.moving
                else f"pass ints in 0..{self.snapshots - 1}",
            )
        return t

    def _start_snapshots(self, idx, st, tgt, t0, explicit: bool) -> torch.Tensor:
        """The start snapshots of robots ``idx`` (moving twins); random starts a mover covers at a given ``t0`` are
        redrawn (in place in ``st``) among the cells free then."""
        n, dev = self.mdp.num_cells, self.device
        if t0 is None:  # uniform among the snapshots in which the start is free (one exists: it is no wall)
            free = ~self.covered.view(self.snapshots, n)[:, st].T
            return torch.multinomial(free.float(), 1, generator=self.gen).squeeze(1)
        bad = self.covered[t0 * n + st]
        if bool(bad.any()):
            if explicit:
                c = int(st[bad][0])
                raise InvalidCoordinatesError(
                    f"reset_where: start cell {tuple(int(v) for v in self.mdp.xy(c))} is covered by a mover at "
                    f"snapshot {int(t0[bad][0])}",
                    hint="pick a start that is free at t0, or another t0",
                )
            b = torch.nonzero(bad, as_tuple=True)[0]
            cells = torch.arange(n, device=dev)
            if self.aug_obstacles:
                ok = self.adist[idx[b]] > 0
            else:
                ok = (self.component[None] == self.component[tgt[b]][:, None]) & (cells[None] != tgt[b][:, None])
            ok &= ~self.covered.view(self.snapshots, n)[t0[b]]
            if not bool(ok.any(1).all()):
                raise InvalidCoordinatesError(
                    "reset_where: movers cover every start cell that reaches the target at t0",
                    hint="pass another t0, or no t0",
                )
            st[b] = torch.multinomial(ok.float(), 1, generator=self.gen).squeeze(1)
        return t0

    def _cells(self, name: str, cells, k: int) -> torch.Tensor:
        """``cells`` (``k`` free cell indices, one per robot reset) as a long tensor, or
        :class:`InvalidCoordinatesError` naming ``name`` (fractions, a wrong count, an index off the grid or a blocked
        cell)."""
        t = torch.as_tensor(cells, device=self.device)
        if t.dtype.is_floating_point or t.dtype == torch.bool or t.is_complex():
            raise InvalidCoordinatesError(
                f"reset_where {name} must be integer cell indices (iy * nx + ix), got {t.dtype}",
                hint=f"pass {k} ints",
            )
        if t.numel() != k:
            raise InvalidCoordinatesError(
                f"reset_where {name}: {t.numel()} cells for {k} robots", hint=f"pass one cell per robot reset ({k})"
            )
        t = t.reshape(k).long()
        inside = (t >= 0) & (t < self.mdp.num_cells)
        if not bool((inside & (self.component[t.clamp(0, self.mdp.num_cells - 1)] >= 0)).all()):  # -1: blocked
            raise InvalidCoordinatesError(
                f"reset_where {name}: a cell is off the {self.mdp.nx} x {self.mdp.ny} grid or not free",
                hint=f"pass free cell indices in 0..{self.mdp.num_cells - 1}",
            )
        return t

    # -- obstacle augmentation -------------------------------------------------------------------------------------
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
                d = torch.as_tensor(
                    self.mdp.bfs_distances_many(np.array(missing)), dtype=torch.int32, device=self.device
                )
                self.dist = torch.cat([self.dist, d])
            else:
                self.dist = torch.cat(
                    [self.dist, torch.zeros((len(missing), 0), dtype=torch.int32, device=self.device)]
                )
            self._build_fast()
        return torch.as_tensor([self._pool_pos[c] for c in cells], dtype=torch.long, device=self.device)

    def observe(self) -> torch.Tensor:
        """``float32[num_envs, obs_dim]`` observations of the current cells (at each robot's snapshot)."""
        if self._fast_obs:  # the same bytes as the concatenation below, written once
            obs = self._obs_wide.index_select(0, self.cell)  # index_select: 7x faster than cell_part[cell] here
            if self._obs_target is not None:
                col = obs.view(torch.int64).select(1, self.cell_part.shape[1] // 2)
                torch.index_select(self._obs_target, 0, self.target, out=col)
            elif self.target_part.shape[1]:
                obs[:, self.cell_part.shape[1] :] = self.target_part.index_select(0, self.target)
            return obs
        obs = torch.cat(self._table_rows(), 1)
        return obs if self.noise is None else self.noise.apply(obs, self._rows(), self.errors)

    def _rows(self) -> torch.Tensor:
        """The cell-part rows of the robots: their cells, or on a moving twin ``t * cells + cell``."""
        return self.t * self.mdp.num_cells + self.cell if self.moving else self.cell

    def _table_rows(self) -> list[torch.Tensor]:
        """The observation's two parts looked up in the tables, before any noise: the current cells' rows (with
        the extra obstacles) and the targets' rows."""
        # index_select, not table[rows]: the same rows, 7x faster on CPU (31 vs 228 us at 4 096 robots)
        cell_part = self.cell_part.index_select(0, self._rows())
        if self.aug_obstacles and self._nbr_cols is not None:
            # An extra-blocked neighbour reads like a blocked one: radio features 0 (missing) and flag 0.
            hidden = self.extra.gather(1, self.next_cell[self.cell])  # [N, 4]
            cols = self._nbr_cols.to(self.device)
            cell_part[:, cols.reshape(-1)] *= (~hidden).float().repeat_interleave(cols.shape[1], 1)
        if self.aug_obstacles and self._ring.shape[1]:  # and in the wider ring, now and in the snapshot before
            seen = (~self.extra.gather(1, self._ring.index_select(0, self.cell))).float()
            cell_part[:, self.obs_table.ring_columns] *= seen.repeat(1, 2)
        return [cell_part, self.target_part.index_select(0, self.target)]

    def _potential(self, cell: torch.Tensor, target=None, tpool=None) -> torch.Tensor:
        """The shaping potential of robots on ``cell`` (default targets: the robots' own)."""
        target = self.target if target is None else target
        tpool = self.tpool if tpool is None else tpool
        if self.potential == "geodesic" and self.aug_obstacles and self.aug_potential == "replan":
            return self.adist.gather(1, cell[:, None]).squeeze(1).float()
        if self.potential == "geodesic":
            return self.dist[tpool, cell].float()
        dx, dy = self.ix[target] - self.ix[cell], self.iy[target] - self.iy[cell]
        return torch.sqrt(dx * dx + dy * dy)

    def _reward(self, cell, nxt, target, tpool, penalised, reached) -> torch.Tensor:
        """The reward of moves ``cell -> nxt`` (elementwise; robots in a step, or every entry of the fast path's
        table): :func:`~dtradar_rl.task.rewards.reward_fn` in float32."""
        dx, dy = self.ix[target] - self.ix[nxt], self.iy[target] - self.iy[nxt]
        if self.potential:
            pb, pa = self._potential(cell, target, tpool), self._potential(nxt, target, tpool)
        else:
            pb = pa = torch.zeros((), device=self.device)
        return reward_fn(
            self.reward_name,
            d2_after=dx * dx + dy * dy,
            pot_before=pb,
            pot_after=pa,
            collision=penalised.float(),
            reached=reached.float(),
            diag2=self.mdp.diag2,
        ).float()

    def shortest_moves(self) -> torch.Tensor:
        """``bool[num_envs, 4]``: the moves that take each robot one cell closer to its target along a breadth-first
        shortest path of the map the episode is played on (with obstacle augmentation, the robot's augmented grid).

        This is the twin's own answer, known because the table is: :mod:`dtradar_rl.train.dqn` uses it as the expert of
        a large-margin loss (``--expert-weight``), e.g. when fine-tuning on a changed twin
        (:mod:`dtradar_rl.experiments.adapt`). A robot with no such move (cut off from its target) gets an all-false
        row. Needs the ``geodesic`` reward, whose distance tables it reads. On a moving twin: the static map's
        moves (movers ignored)."""
        if self.potential != "geodesic":
            raise InvalidCoordinatesError(
                "shortest moves read the breadth-first distance tables of the geodesic "
                f"reward; this env uses {self.reward_name!r}",
                hint="use reward='geodesic'",
            )
        nxt = self.next_cell[self.cell]  # [N, 4]; a colliding move stays on the cell, so it never gets closer
        if self.aug_obstacles:
            here, there = self.adist.gather(1, self.cell[:, None]), self.adist.gather(1, nxt)
        else:
            here, there = self.dist[self.tpool, self.cell][:, None], self.dist[self.tpool[:, None], nxt]
        return (there >= 0) & (there == here - 1) & ~self.collides[self.cell]

    def step(self, actions: torch.Tensor):
        """Move every robot; returns ``(next_obs, reward, terminated, truncated, info)`` (no auto-reset).

        ``info``: ``collision`` (bool[N]: the move failed), ``is_success`` (= terminated), ``steps`` (steps taken
        this episode); on a moving twin also ``mover_collision`` (the failed move aimed at a mover), ``mover_hit`` (a
        mover walked onto the robot) and ``t`` (each robot's snapshot now).
        """
        a = actions.to(self.device, torch.long)
        if self._fast_step and a.shape == self.cell.shape and (a.device.type != "cpu" or self._valid_actions(a)):
            return self._step_fast(a)
        cell = self.cell
        nxt = self.next_cell[cell, a]
        collision = self.collides[cell, a]
        if self.aug_obstacles:  # a move into an extra obstacle collides: the robot stays
            hit = self.extra.gather(1, nxt[:, None]).squeeze(1)
            nxt = torch.where(hit, cell, nxt)
            collision = collision | hit
        penalised = collision
        if self.moving:  # the next snapshot's blocked mask: a mover there refuses the move; one may walk onto us
            t1 = self.t_next[self.t]
            now, base = self.t * self.mdp.num_cells, t1 * self.mdp.num_cells
            swap = self.covered[now + nxt] & self.covered[base + cell]  # a mover coming the other way
            mover_collision = (self.covered[base + nxt] | swap) & ~collision
            nxt = torch.where(mover_collision, cell, nxt)
            mover_hit = self.covered[base + nxt]
            collision = collision | mover_collision
            penalised = collision | mover_hit
            self.t = t1
        reached = nxt == self.target
        reward = self._reward(cell, nxt, self.target, self.tpool, penalised, reached)
        self.cell = nxt
        self.steps += 1
        self._draw_errors()
        terminated = reached
        truncated = (self.steps >= self.max_steps) & ~terminated
        info = {"collision": collision, "is_success": reached, "steps": self.steps.clone()}
        if self.moving:
            info.update(mover_collision=mover_collision, mover_hit=mover_hit, t=self.t.clone())
        return self.observe(), reward, terminated, truncated, info
