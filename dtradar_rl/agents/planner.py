"""The classical baseline: localise by radio fingerprint, plan breadth-first on the blueprint map, replan on surprises.

What a user would pick without learning. At every step each robot

1. **localises** from the radio features of its cell alone: the nearest fingerprint (the 8 z-scored radio features
   of the observation: AoA, AoD, coefficient, delay, phase; of every transmitter on a twin with several, 0 where one
   has no path) among the free cells of the *blueprint* table with radio features from at least one transmitter
   (restricting the match to the believed cell's neighbours, a tracking filter, was measured worse: 0.81 against
   0.84 on the cubicle's dynamic twin, as one wrong belief then never recovers);
2. **senses**: a neighbour whose radio features are missing (has-radio flag 0) is occupied; so is the cell a move
   just failed to enter (the fingerprint did not change: a collision). Both go into a per-robot map of obstacles
   sensed this episode, on top of the blueprint's own blocked cells;
3. **plans** breadth-first from the target (its coordinates are in the observation) on that map and takes a move
   along a shortest path. If the sensed obstacles cut the target off (a mislocalisation can do that) the robot
   forgets them and replans on the blueprint alone.

On a moving twin (:mod:`dtradar_rl.task.grid_mdp`) the robot **forgets** what it sensed at every step: a mover that
was next to it a step ago may have walked on, so each step plans breadth-first on the static map (the blueprint's, or
a moving twin's :func:`~dtradar_rl.task.moving_masks.background`) plus only what it senses now (neighbours without radio
features in the current snapshot, and the cell a move just failed to enter). It is a static search on the current
blocked mask, replanned every step: it does not predict where movers go. Where the detour around what it senses is
more than :data:`DETOUR_MARGIN` steps longer than the static map's path (or there is none) it keeps to the static
path and moves towards the sensed cell anyway: the mover has usually gone by the next snapshot, and if not the move
bumps, which is how a four-action robot waits. In a periodic world such a deterministic planner can still fall into
a loop in step with a mover (detour, mover moves, back, ...), so on a moving twin a robot that stands on a cell for
the :data:`ESCAPE_AFTER` + 1-th time this episode takes a random move that the static map allows (towards a sensed
mover too, which may be gone by then; a seeded generator, restarted by ``env_for``: evaluations repeat).

**Giving way** (on a moving twin, ``predict``, the default). A mover collision is a move into a cell a mover covers
at the *next* snapshot, which the robot cannot observe; it predicts it from what it senses now. A robot with a mover
in a neighbouring cell takes the move least likely to meet it (:func:`predicted_risk`, measured rates of each move
relative to the mover, plus a little for leaving the plan; the plan orders moves of equal risk): a step to the side
of the mover first, then into the mover where the plan pushes there anyway (it has usually walked on), straight away
from it (an oncoming mover covers the cell behind the robot too), and last a wait by a wall bump (it never collides,
but the mover walks onto a robot that stays, and a robot that stays beside the movers meets more of them). A mover on
the robot's own cell blanks its observation, so the robot then believes it is where its last move led rather than
matching a fingerprint of zeros. What this cannot avoid is a mover it has not sensed: the movers of the ray-traced
twins are 2 x 2 cells and walk 2-3 cells a snapshot, so about half of the mover collisions (0.28 of 0.54 per
episode on cubicle/moving) come from a mover that was two or more cells away the step before, where a robot that
senses its four neighbours sees nothing.

:class:`FingerprintPlanner` has the part of :class:`~dtradar_rl.agents.policy.Policy` the evaluation loop uses
(``env_for``, ``act``, ``obs_preset``, ``meta``), so :func:`~dtradar_rl.evaluation.evaluate.evaluate_twins` runs it
unchanged. It keeps per-robot state between calls and starts afresh in ``env_for`` (one batch of episodes per env).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.grid_search import GridSearch
from dtradar_rl.agents.honest_reader import honest_reader
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import flag_columns
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.moving_masks import background
from dtradar_rl.task.observations import PAPER_COLUMNS, Normalizer, build_observations, check_transmitters
from dtradar_rl.task.sensing import sensing_for

#: Observation columns of the cell's own radio features (``neighbors`` preset) with one transmitter; with several,
#: :attr:`~dtradar_rl.task.observations.ObservationTable.radio_columns` (every transmitter's).
RADIO_COLUMNS = slice(2, len(PAPER_COLUMNS))
#: On a moving twin: earlier stands on a cell after which the robot leaves it by a random move (loop escape), and the
#: extra steps of a detour around sensed cells worth taking rather than waiting on the static path. Chosen on the
#: synthetic moving twins (12 x 8, 16 x 10, 42 x 18; 200 pairs): without the escape a robot in step with a mover
#: that walks two cells back and forth never got past it (success 0.83-0.93 on the small ones, 1.0 with it).
ESCAPE_AFTER = 2
DETOUR_MARGIN = 2
ESCAPE_SEED = 0


class FingerprintPlanner:
    """Breadth-first planning on a map (normally the blueprint) with fingerprint localisation (module docstring)."""

    obs_preset = "neighbors"

    def __init__(
        self, blueprint: Dataset, normalizer: Normalizer | None = None, device: str = "cpu", sensing: str = "radio"
    ):
        self.normalizer = normalizer or Normalizer.fit(blueprint)
        #: honest sensing (:mod:`dtradar_rl.task.sensing`; the default): one-shot localisation by the most likely
        #: fingerprint and the proximity sensor; ``privileged``: the nearest fingerprint of the ``neighbors``
        #: observation and its neighbours' has-radio flags (radio of other cells of the navigated twin)
        self.sensing = sensing_for(sensing)
        self._honest = None if self.sensing.privileged else honest_reader(blueprint, sensing, device)
        if self._honest is not None:
            self.obs_preset = "honest"
        blueprint = background(blueprint)  # a moving twin's static map and fingerprints
        self.mdp = GridMDP.from_dataset(blueprint)
        self.device = torch.device(device)
        table = build_observations(blueprint, "neighbors", self.normalizer)
        raw = blueprint.grid(list(self.normalizer.columns)).reshape(self.mdp.num_cells, -1)
        has_radio = self.mdp.free & np.asarray(table.has_radio, bool)  # from any transmitter
        t = lambda a, dt=torch.float32: torch.as_tensor(np.ascontiguousarray(a), dtype=dt, device=self.device)
        #: the observation columns of a fingerprint: the cell's radio features of every transmitter
        self.radio_columns = _columns(table.radio_columns, self.device)
        #: fingerprints of the blueprint's free cells with radio features, and which cells they are
        self.cells = t(np.flatnonzero(has_radio), torch.long)
        self.fingerprints = t(table.cell_part[has_radio][:, table.radio_columns])
        # every cell's (x, y) as an observation shows a target there (the table blanks blocked cells; a dynamic
        # twin's target may sit on one of them)
        xy = [self.normalizer.columns.index(c) for c in PAPER_COLUMNS[:2]]
        self.positions = t(self.normalizer.apply(raw.astype(np.float64))[:, xy])
        self.next_cell = t(self.mdp.next_cell, torch.long)
        self.wall = t(self.mdp.collides, torch.bool)  # moves the blueprint itself forbids
        self.blocked = t(self.mdp.blocked.ravel(), torch.bool)
        self.search = GridSearch(self.mdp, self.device)
        self.flags = flag_columns()
        self.meta: dict[str, Any] = {
            "dataset": {"name": blueprint.name, "version": blueprint.version},
            "stats": {},
            "path": "planner",
            "sensing": self.sensing.name,
        }
        self.config = None
        self._n = -1
        #: forget sensed obstacles at every step (set by :meth:`env_for` on a moving twin)
        self.forget = False
        #: on a moving twin, give way to a mover sensed next to the robot (:func:`predicted_risk`)
        self.predict = True

    # -- the Policy interface used by dtradar_rl.evaluation.evaluate
    # -------------------------------------------------------------
    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        self._start(num_envs)
        self.forget = ds.is_moving
        if self._honest is not None:
            return self._honest.env_for(ds, num_envs, **kwargs)
        return BatchedNavEnv.from_dataset(ds, num_envs, obs="neighbors", normalizer=self.normalizer, **kwargs)

    def observations(self, ds: Dataset):
        return build_observations(ds, "neighbors", self.normalizer)

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """One move per robot; ``shield`` is accepted and ignored (the planner never enters a sensed obstacle)."""
        obs = obs.to(self.device)
        if obs.shape[0] != self._n:
            self._start(obs.shape[0])
        n = obs.shape[0]
        rows = torch.arange(n, device=self.device)
        if self._honest is not None:
            fp, cell, target, occupied, stuck, blank = self._honest.read(obs, self._last_action)
        else:
            fp = obs[:, self.radio_columns]
            gap = torch.cdist(fp, self.fingerprints)  # [n, fingerprints]
            cell = self.cells[gap.argmin(1)]
            target = torch.cdist(obs[:, -2:], self.positions).argmin(1)
            # a collision: the same fingerprint after a move the plan expected to succeed
            stuck = (self._last_action >= 0) & (fp == self._last_fp).all(1)
            # a mover on the robot's cell blanks it (no position, no radio)
            blank = (obs[:, : len(PAPER_COLUMNS)] == 0).all(1) & (self._last_action >= 0)
            occupied = obs[:, self.flags] < 0.5  # [n, 4]

        if self.forget:  # a moving twin: plan on what is sensed now only
            self.sensed.zero_()
        if self.forget and self.predict:
            # a blank own cell: any fingerprint would match by chance, so the robot believes it is where its last
            # move led, and a blank twice is no collision
            cell = torch.where(blank, self.next_cell[self._last_cell, self._last_action.clamp(min=0)], cell)
            stuck &= ~blank
        if bool(stuck.any()):
            r = rows[stuck]
            aimed = self.next_cell[self._last_cell[r], self._last_action[r]]
            self.sensed[r, aimed] = True
        nbr = self.next_cell[cell]
        hit = occupied & ~self.wall[cell]
        self.sensed[rows[:, None].expand(n, 4)[hit], nbr[hit]] = True
        self.sensed[rows, target] = False  # the target is reachable by construction of the pairs
        self.sensed[rows, cell] = False

        # replan only robots whose map or target changed since their last plan
        stale = (self._plan_target != target) | (self.sensed != self._plan_sensed).any(1)
        if bool(stale.any()):
            self._dist[stale] = self._bfs(target[stale], self.sensed[stale])
        lost = self._dist[rows, cell] < 0
        if bool(lost.any()):  # the sensed map cut the target off: forget it and trust the blueprint
            self.sensed[lost] = False
            self._dist[lost] = self._bfs(target[lost], self.sensed[lost])
        self._plan_target, self._plan_sensed = target, self.sensed.clone()
        dist = self._dist
        d_next = dist.gather(1, nbr).float()
        refused = (d_next < 0) | self.wall[cell] | occupied
        if self.forget:  # a moving twin: wait on the static path rather than take a long detour (module docstring)
            fresh = self._static_target != target
            if bool(fresh.any()):
                self._static_dist[fresh] = self._bfs(target[fresh], torch.zeros_like(self.sensed[fresh]))
                self._static_target = target.clone()
            here0, here1 = self._static_dist[rows, cell], self._dist[rows, cell]
            keep = (here1 < 0) | (here1 > here0 + DETOUR_MARGIN) | lost
            d_next = torch.where(keep[:, None], self._static_dist.gather(1, nbr).float(), d_next)
            here = torch.where(keep, here0, here1)
            walls = (d_next < 0) | self.wall[cell]
            refused = walls | occupied
            # no free move gets closer on the plan: push towards the sensed cell (a bump waits for it to go)
            push = ~((d_next < here[:, None]) & ~refused).any(1)
            refused = torch.where(push[:, None], walls, refused)
        d_next[refused] = float("inf")
        action = d_next.argmin(1)
        if self.forget:  # loop escape on a moving twin (module docstring)
            self._visits[rows, cell] += 1
            loop = self._visits[rows, cell] > ESCAPE_AFTER
            if bool(loop.any()):
                allowed = ~self.wall[cell][loop]  # a move towards a sensed mover too: it may have gone by then
                score = torch.rand(allowed.shape, generator=self._escape_gen, device=self.device)
                action[loop] = torch.where(allowed, score, -1.0).argmax(1)
            if self.predict:
                action = self._give_way(action, occupied & ~self.wall[cell], self.wall[cell], d_next, loop)
        self._last_fp, self._last_cell, self._last_action = fp.clone(), cell, action
        return action

    # -- internals ------------------------------------------------------------------------------------------------
    def _give_way(self, action, movers, walls, d_next, escaping):
        """The moves of robots with a mover next to them (``movers bool[n, 4]``: the neighbours a mover covers now),
        under :func:`predicted_risk`: the least risky move, the plan's (``d_next``) first among equals."""
        near = movers.any(1) & ~escaping
        if not bool(near.any()):
            return action
        risk = predicted_risk(movers[near], walls[near], off_plan=~torch.isfinite(d_next[near]))
        least = risk <= risk.min(1, keepdim=True).values + 1e-6
        action = action.clone()  # the least risky moves, the plan's best of them
        action[near] = torch.where(least, d_next[near].nan_to_num(posinf=1e9), torch.inf).argmin(1)
        return action

    def _start(self, n: int) -> None:
        self._n = n
        self.sensed = torch.zeros((n, self.mdp.num_cells), dtype=torch.bool, device=self.device)
        self._last_fp = torch.full((n, self.fingerprints.shape[1]), float("nan"), device=self.device)
        self._last_cell = torch.zeros(n, dtype=torch.long, device=self.device)
        self._last_action = torch.full((n,), -1, dtype=torch.long, device=self.device)
        self._plan_target = torch.full((n,), -1, dtype=torch.long, device=self.device)
        self._plan_sensed = self.sensed.clone()
        self._dist = torch.full((n, self.mdp.num_cells), -1, dtype=torch.long, device=self.device)
        self._visits = torch.zeros((n, self.mdp.num_cells), dtype=torch.int32, device=self.device)
        self._static_target = torch.full((n,), -1, dtype=torch.long, device=self.device)
        self._static_dist = torch.full((n, self.mdp.num_cells), -1, dtype=torch.long, device=self.device)
        self._escape_gen = torch.Generator(device=self.device)
        self._escape_gen.manual_seed(ESCAPE_SEED)

    def _bfs(self, targets: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
        """``long[k, cells]`` breadth-first steps to ``targets`` on the map with ``extra`` cells blocked too
        (-1: blocked or cut off): :class:`~dtradar_rl.agents.grid_search.GridSearch`."""
        return self.search(targets, extra)


#: The opposite of each action (X- <-> X+, Y- <-> Y+).
OPPOSITE = (1, 0, 3, 2)
#: How often each move meets a mover at the next snapshot (a mover collision or a hit), by where it leads relative to
#: a mover sensed in one neighbour: measured over every free cell and snapshot of cubicle/moving (meeting/moving in
#: brackets) with one mover next to the robot: to either side 0.135 (0.119), into the mover 0.26 (0.24: it walks on
#: at 2-3 cells a snapshot, unless it comes onto the robot's cell), straight away from it 0.30 (0.24: an oncoming
#: mover covers the cell behind the robot too). A bump into a wall (the robot waits) never collides, but the mover
#: walks onto a robot that stays as often as a move into it fails: 0.25, just under a move into the mover.
RISK_TOWARD, RISK_AWAY, RISK_SIDE, RISK_WALL = 0.26, 0.30, 0.13, 0.25
#: Added to the risk of a move the plan would not take (a detour, a wall bump, a push into a mover it can go round):
#: a robot that stays beside the movers meets more of them later. With it, on cubicle/moving (500 episodes) the
#: planner had 0.48 mover collisions and 0.26 hits per episode; with risk alone 0.54 and 0.34 (it waited by wall
#: bumps), and with a wall bump rated 0 (wait whenever possible) 0.60 and 0.34.
RISK_OFF_PLAN = 0.1


def predicted_risk(movers: torch.Tensor, walls: torch.Tensor, off_plan: torch.Tensor | None = None) -> torch.Tensor:
    """``float[n, 4]``: how likely each move is to meet a mover at the next snapshot, from the neighbours a mover
    covers now (``movers bool[n, 4]``) and the static walls around the robot (``walls bool[n, 4]``), plus
    :data:`RISK_OFF_PLAN` for each move the robot's plan (``off_plan bool[n, 4]``) would not take."""
    opposite = list(OPPOSITE)
    toward = movers.float()
    away = movers[:, opposite].float()
    side = movers.sum(1, keepdim=True).float() - toward - away
    risk = RISK_TOWARD * toward + RISK_AWAY * away + RISK_SIDE * side
    risk = torch.where(walls, torch.full_like(risk, RISK_WALL), risk)
    return risk if off_plan is None else risk + RISK_OFF_PLAN * off_plan.float()


class MoverGuard:
    """:func:`predicted_risk` for a learned policy on a moving twin: it locates each robot by the position in its
    observation (the cell whose ``x_m, y_m`` are nearest), tells movers from walls by the twin's static map, and
    makes a robot with a mover next to it take the least risky move, the policy's Q-values ordering moves of equal
    risk. A robot a mover stands on reads its own cell blank and is left alone (it cannot tell where it is). A policy
    with the wait action (five Q-values) may wait: rated as a wall bump (the robot stays) off the plan."""

    def __init__(self, ds: Dataset, normalizer: Normalizer, device: str | torch.device = "cpu"):
        check_transmitters(normalizer, ds)
        static = background(ds)
        mdp = GridMDP.from_dataset(static)
        raw = static.grid(list(normalizer.columns)).reshape(mdp.num_cells, -1).astype(np.float64)
        xy = [normalizer.columns.index(c) for c in PAPER_COLUMNS[:2]]
        self.positions = torch.as_tensor(normalizer.apply(raw)[:, xy], dtype=torch.float32, device=device)
        self.walls = torch.as_tensor(mdp.collides, device=device)
        self.flags = flag_columns()

    def give_way(self, obs: torch.Tensor, q: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        flat, shape = obs.reshape(-1, obs.shape[-1]), action.shape
        located = (flat[:, : len(PAPER_COLUMNS)] != 0).any(1)
        walls = self.walls[torch.cdist(flat[:, :2], self.positions).argmin(1)]
        movers = (flat[:, self.flags] < 0.5) & ~walls & located[:, None]
        near = movers.any(1)
        if not bool(near.any()):
            return action
        flags = flat[near][:, self.flags] > 0.5  # what the plain shield allows is the policy's "plan"
        risk = predicted_risk(movers[near], walls[near], off_plan=~flags)
        if q.shape[-1] > 4:  # the wait: a robot that stays, as a wall bump does, and off the plan as one is
            risk = torch.cat([risk, torch.full_like(risk[:, :1], RISK_WALL + RISK_OFF_PLAN)], 1)
        least = risk <= risk.min(1, keepdim=True).values + 1e-6
        action = action.reshape(-1).clone()
        action[near] = torch.where(least, q.reshape(-1, q.shape[-1])[near], -torch.inf).argmax(1)
        return action.reshape(shape)


def _columns(cols: list[int], device: torch.device) -> slice | torch.Tensor:
    """``cols`` as a slice where they are a run (one transmitter: a view, as the planner always read them), else an
    index tensor."""
    if cols == list(range(cols[0], cols[-1] + 1)):
        return slice(cols[0], cols[-1] + 1)
    return torch.as_tensor(cols, dtype=torch.long, device=device)


def planner_for_scene(scene: str, device: str = "cpu", sensing: str = "radio") -> FingerprintPlanner:
    """The baseline with the blueprint of ``scene`` as its map and fingerprint table, observing with ``sensing``."""
    from dtradar_rl.task.twins import load_dataset

    return FingerprintPlanner(load_dataset(f"{scene}/blueprint"), device=device, sensing=sensing)
