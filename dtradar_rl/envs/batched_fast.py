"""The batched env's fast path: precomputed tables for a static twin without obstacle augmentation.

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
outside 0..3, the wait action) takes the general path, which ``fast_path=False`` forces; a test checks that both
give the same trajectories bit for bit (observations, rewards, terminations, info, state, random streams). Measured
figures are in :meth:`BatchedNavEnv._step_fast`.
"""

from __future__ import annotations

import torch

#: Most entries of a fast-path table (the rewards: pool targets x cells x 4 actions, float32, 32 MB; the random
#: starts: pool targets x largest component); above it the env keeps the general path (see the module docstring).
FAST_TABLE_MAX = 8_000_000


class FastPathMixin:
    """The fast path of :class:`~dtradar_rl.envs.batched.BatchedNavEnv` (its attributes, its general step)."""

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
        self._fast_step = plain and not self.wait_action and p * n * 4 <= FAST_TABLE_MAX  # its tables: 4 moves
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
