"""A learnt table followed by a robot that is not told its cell: the localisation filter's belief votes for a move.

A tabular batch learner (:mod:`dtradar_rl.tabular.batch`) learns one move (CE, VI-LCB) or one distribution over the
four moves (Π_b-SPIBB) per ``(cell, target)`` from a log's cells and moves: the log's cell labels are training data,
recorded when the data was collected, like the map itself. At deployment the robot does not know its cell. It
carries the default agent's localisation filter (:class:`~dtradar_rl.agents.radio_filter.RadioFilterAgent`: a
belief over the blueprint's cells, moved by its odometry and weighed by its own cell's radio and its proximity
sensor) and takes the move its table gives the most belief to,

    a = argmax_a  Σ_s  b(s) · π(a | s, target)

(the voting heuristic of Cassandra, Kaelbling and Kurien 1996; a deterministic table's π is one-hot), never a move
its proximity sensor reports blocked. A robot whose odometry shows it going back and forth takes a seeded random
move, as the default agent does. With ``replan`` (CE and VI-LCB, the learners that take forbidden moves), the
obstacles the filter senses where the map has none (a neighbour sensed blocked, or a bump, while the belief is sure
of the robot's cell) are forbidden moves, and the robot's table is learnt again for its target without them, on the
same empirical model (the privileged tables with senses do the same from the true cell: :mod:`dtradar_rl.tabular.
sensing`). Nothing in the decision reads the robot's position or another cell's radio: its observation is the honest
one of :mod:`dtradar_rl.task.sensing`.

    policy = FilterTablePolicy(blueprint, grid_table, targets, "CE", FilterConfig(scene="cubicle"))
    metrics, _ = evaluate(policy, load_dataset("cubicle/dynamic"), noise="realistic")
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.tabular.batch import BatchConfig, EmpiricalModel, learn

#: Robots whose votes are summed at once (``cells x robots x 4`` floats): a city quadrant's 10 000 cells stay near
#: 40 MB per chunk.
CHUNK_ELEMENTS = 1 << 22


class FilterTablePolicy:
    """A table over the blueprint's cells (``int64[H*W, K]`` moves or ``float[H*W, K, 4]`` probabilities, column
    ``j`` for target cell ``targets[j]``) followed through the localisation filter's belief (module docstring). It has
    the part of :class:`~dtradar_rl.agents.policy.Policy` the evaluation uses (``env_for``, ``act``, ``obs_preset``,
    ``meta``, ``config``)."""

    obs_preset = "honest"

    def __init__(
        self,
        blueprint: Dataset,
        table: np.ndarray,
        targets: np.ndarray,
        name: str = "table",
        filter_config: FilterConfig | None = None,
        device: str = "cpu",
        escape: bool = True,
        replan: tuple[str, EmpiricalModel, BatchConfig] | None = None,
    ):
        self.agent = RadioFilterAgent(blueprint, filter_config, device)
        self.config = self.agent.config
        cells = self.agent.mdp.num_cells
        table = np.asarray(table)
        self.targets = np.asarray(targets, np.int64).ravel()
        if table.shape[:2] != (cells, self.targets.size) or table.shape[2:] not in ((), (4,)):
            raise InvalidSettingError(
                f"a table over {blueprint.name} is int64[{cells}, {self.targets.size}] or "
                f"float[{cells}, {self.targets.size}, 4], got shape {table.shape}",
                hint="one row per blueprint cell (iy * nx + ix), one column per target",
            )
        if table.ndim == 2:  # one-hot: a deterministic table votes with all of a cell's belief
            table = np.eye(4, dtype=np.float32)[table]
        self.probs = torch.as_tensor(table, dtype=torch.float32, device=self.agent.device)  # [cells, K, 4]
        self._column = np.full(cells, -1, np.int64)
        self._column[self.targets] = np.arange(self.targets.size)
        self.name, self.escape, self.replan = name, escape, replan
        if replan is not None:
            tab = replan[1].tab
            cells_of = tab.mdp.next_cell[tab.cells]  # [N, 4] the grid cell each state's moves lead to
            self._states, self._after = tab.cells, cells_of
            self._moves_away = cells_of != tab.cells[:, None]
        self.meta: dict[str, Any] = {
            "dataset": dict(self.agent.meta["dataset"]),
            "path": name,
            "sensing": self.agent.sensing.name,
            "localise": "filter",
            "stats": {},
        }
        self._log_belief: torch.Tensor | None = None
        self._col = torch.zeros(0, dtype=torch.long)

    def env_for(self, ds: Dataset, num_envs: int, *, noise=None, seed: int = 0, **kwargs) -> HonestNavEnv:
        """The honest env of ``ds`` (a fresh belief per robot) under ``noise`` (default: the noise the filter
        assumes, its config's)."""
        env = self.agent.env_for(ds, num_envs, noise=noise or self.config.noise, seed=seed, **kwargs)
        self._start(num_envs)
        return env

    def _start(self, n: int) -> None:
        dev = self.agent.device
        self._log_belief = self.agent.log_prior.expand(n, -1).clone()
        self._col = torch.zeros(n, dtype=torch.long, device=dev)
        self._has_own = torch.zeros(n, dtype=torch.bool, device=dev)
        self._own: torch.Tensor | None = None  # [n, cells, 4] a re-planned robot's own table, made when first needed
        self._plan_sensed = torch.zeros((n, self.agent.mdp.num_cells), dtype=torch.bool, device=dev)

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """One move per robot: the table's vote over the belief among the moves the proximity sensor allows
        (``shield`` is accepted and ignored)."""
        agent = self.agent
        obs = obs.to(agent.device)
        if self._log_belief is None or self._log_belief.shape[0] != obs.shape[0]:
            agent._start(obs.shape[0])
            self._start(obs.shape[0])
        blocked, moved, last, fresh = agent.readings(obs)
        if bool(fresh.any()):
            idx = torch.nonzero(fresh, as_tuple=True)[0]
            self._col[idx] = self._columns(torch.cdist(obs[idx, -2:], agent.positions).argmin(1))
            self._has_own[idx] = False
            agent._new_episodes(fresh, obs[:, -2:])  # its target and no sensed obstacles yet
        with torch.no_grad():
            self._log_belief, belief = agent.belief_step(self._log_belief, obs)
            if self.replan is not None:
                agent._sense_obstacles(belief, blocked, moved, last, fresh)
                self._replan()
            votes = self._votes(belief)
        allowed = ~blocked if agent.sensing.proximity else torch.ones_like(blocked)
        allowed = allowed | ~allowed.any(1, keepdim=True)  # boxed in: any move (it bumps, and learns so)
        # a move with no vote that the sensor allows still beats a blocked one
        action = torch.where(allowed, votes, torch.full_like(votes, -1.0)).argmax(1)
        return agent._escape(action, last, moved, fresh, blocked) if self.escape else action

    def _columns(self, target_cells: torch.Tensor) -> torch.Tensor:
        """The table column of each target cell; -1 for a target the table has none for: such a robot (in an
        evaluation, one the env switched on again after its episode ended, whose moves are not scored) has no vote
        and takes the first move its sensor allows. Learn a table over every cell to follow it to any target."""
        column = self._column[target_cells.cpu().numpy()]
        self.meta["stats"]["uncovered_targets"] = self.meta["stats"].get("uncovered_targets", 0) + int(
            (column < 0).sum()
        )
        return torch.as_tensor(column, device=self.agent.device)

    def _replan(self) -> None:
        """A new table for every robot that sensed a new obstacle: its target's, learnt without the moves into what
        it sensed (a robot without a column keeps none)."""
        agent = self.agent
        changed = (agent.sensed != self._plan_sensed).any(1) & (self._col >= 0)
        self._plan_sensed = agent.sensed.clone()
        if not bool(changed.any()):
            return
        name, model, cfg = self.replan
        idx = torch.nonzero(changed, as_tuple=True)[0]
        sensed = agent.sensed[idx].cpu().numpy()
        forbidden = sensed[:, self._after] & self._moves_away[None]  # [k, N, 4]
        table = learn(name, model, agent.target[idx].cpu().numpy(), cfg, forbidden)  # [k, N]
        own = np.zeros((idx.numel(), agent.mdp.num_cells, 4), np.float32)
        own[:, self._states] = np.eye(4, dtype=np.float32)[table]
        if self._own is None:
            self._own = torch.zeros((self._col.numel(), agent.mdp.num_cells, 4), device=agent.device)
        self._own[idx] = torch.as_tensor(own, device=agent.device)
        self._has_own[idx] = True
        self.meta["stats"]["replans"] = self.meta["stats"].get("replans", 0) + int(idx.numel())

    def _votes(self, belief: torch.Tensor) -> torch.Tensor:
        """``float32[n, 4]``: Σ_s b(s) π(a | s, target) per robot, robots in chunks."""
        n, cells = belief.shape
        step = max(1, CHUNK_ELEMENTS // (4 * cells))
        out = torch.empty((n, 4), device=belief.device)
        for i in range(0, n, step):
            j = slice(i, i + step)
            col = self._col[j]
            pi = self.probs[:, col.clamp(min=0)]  # [cells, robots, 4]
            if self._own is not None and bool(self._has_own[j].any()):
                pi = torch.where(self._has_own[j][None, :, None], self._own[j].transpose(0, 1), pi)
            out[j] = torch.einsum("rc,cra->ra", belief[j], pi) * (col >= 0)[:, None]
        return out


__all__ = ["FilterTablePolicy"]
