"""The batched env's checks of explicit episode arguments (cells, start snapshots) and the start snapshots of moving
twins.
"""

from __future__ import annotations

import torch

from dtradar_data.core.errors import InvalidCoordinatesError


class ResetChecksMixin:
    """``reset_where``'s argument checks of :class:`~dtradar_rl.envs.batched.BatchedNavEnv`."""

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
