"""Tables with senses: a batch-RL table that avoids what the robot senses and re-plans around it.

A table learnt from logged data (:mod:`dtradar_rl.tabular.batch`) knows the blueprint's walls only. On a dynamic
twin a new object stops it: a deterministic table that bumps into one keeps bumping (the same believed cell, the
same move) until the step limit, which is most of the tables' loss there. A robot senses more than its own radio
features: the has-radio flag of each neighbour (the ``neighbors`` observation: 0 = blocked, off the grid or no path)
and whether its last move changed its cell. :func:`follow_sensing` acts as such a robot, one episode per pair:

1. **localise**: the believed blueprint cell ``b``: the nearest fingerprint at the start, then carried along the
   robot's own moves (it knows which move it made and whether it bumped), :class:`~dtradar_rl.tabular.fingerprints.
   Tracker` with :data:`WINDOW`, started afresh from the nearest fingerprint when the robot believes it stands on
   its target but the episode goes on (a belief known to be wrong); without a tracker, the nearest fingerprint at
   every step (as :class:`~dtradar_rl.tabular.table_policy.TablePolicy` does), which near a new object misleads;
2. **sense**: a neighbour the blueprint says has radio but that senses none is believed blocked, so the move
   ``(b, a)`` towards it is forbidden for the rest of the episode; a move that bumped likewise. A neighbour without
   radio on the blueprint too (a free cell no path reaches) is not read as blocked, nor the target;
3. **re-plan**: when the forbidden set grew, the learner is solved again for the episode's target on the *same*
   empirical model with those moves removed (:func:`~dtradar_rl.tabular.batch.learn` with ``forbidden=``), and the
   robot follows the new table. No new data: the model still knows only the logged moves.

Forbidden moves are kept in believed coordinates, ``(b, a)``, not as cells of the twin: a mislocalised robot forbids
what it believes it saw. The learners re-planned are CE and VI-LCB (Π_b-SPIBB's bootstrapped moves keep the
behaviour's probabilities, which a blocked move would have to give up: not built). Episodes run in lockstep and the
robots that need a new plan at a step are solved together, one call per step. The reward along the way is the
twin's, so an episode's discounted return is exact (cut at the step limit like a rollout).

    paths = follow_sensing("ce", model, table, rows, twin_tab, localisation(blueprint, twin),
                           radio_flags(twin), radio_flags(blueprint), starts, targets,
                           tracker=Tracker(blueprint, twin, WINDOW))
    path_metrics(paths)          # success, SPL, collisions: what the robot does on the twin
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.tabular.batch import BatchConfig, EmpiricalModel, learn
from dtradar_rl.tabular.fingerprints import Tracker
from dtradar_rl.tabular.solver import TabularMDP
from dtradar_rl.task.grid_mdp import ACTION_DELTAS, GridMDP
from dtradar_rl.task.observations import Normalizer, build_observations

#: The learners a sensing robot re-plans with (module docstring).
SENSING: tuple[str, ...] = ("ce", "lcb")
#: Their columns in the offline benchmark: ``<learner>-senses``.
SUFFIX = "-senses"
#: The :class:`~dtradar_rl.tabular.fingerprints.Tracker` window a sensing robot localises with. Measured on Dallas
#: Q3's dynamic twin from expert data (CE / VI-LCB + senses, normalised): 0 (dead reckoning from the first
#: fingerprint) 96.2 / 94.2, 1: 83.0 / 83.2, 2: 81.7 / 78.5, every step's global fingerprint: 72.3 / 72.6; on the
#: blueprint all within 0.1 of each other. Near a new object the fingerprints mislead more than they correct.
WINDOW = 0
#: Value iteration's stopping tolerance when a robot re-plans (the exact solution's is 1e-12). Measured on Dallas Q3's
#: dynamic twin (CE and VI-LCB from expert and medium data): 1e-8, 1e-6 and 1e-4 give the very episodes 1e-12 gives,
#: VI-LCB re-planning in 0.62-0.57x the time at 1e-6 (0.42-0.45x at 1e-4; 1e-6 keeps a margin).
REPLAN_TOL = 1e-6


def radio_flags(ds: Dataset, normalizer: Normalizer | None = None) -> np.ndarray:
    """``bool[H*W]`` the has-radio flag of every cell of ``ds`` (free and with radio features): what a robot senses
    of a neighbour, the same flag the ``neighbors`` observation carries."""
    table = build_observations(ds, "goal", normalizer or Normalizer.fit(ds))
    return np.asarray(table.has_radio, bool)


def neighbour_cells(mdp: GridMDP) -> np.ndarray:
    """``int64[H*W, 4]`` the grid cell next to every cell in action order, -1 off the grid (walls included)."""
    n = mdp.num_cells
    x, y = mdp.xy(np.arange(n))
    out = np.full((n, 4), -1, np.int64)
    for a, (dx, dy) in enumerate(ACTION_DELTAS):
        jx, jy = x + dx, y + dy
        inside = (jx >= 0) & (jx < mdp.nx) & (jy >= 0) & (jy < mdp.ny)
        out[inside, a] = (jy * mdp.nx + jx)[inside]
    return out


def follow_sensing(
    name: str,
    model: EmpiricalModel,
    table: np.ndarray,
    rows: np.ndarray,
    twin: TabularMDP,
    loc: np.ndarray,
    sensed: np.ndarray,
    expected: np.ndarray,
    starts: np.ndarray,
    targets: np.ndarray,
    *,
    cfg: BatchConfig | None = None,
    max_steps: int | None = None,
    tracker: Tracker | None = None,
) -> dict[str, np.ndarray]:
    """Follow learner ``name``'s table as a sensing, re-planning robot on ``twin`` (module docstring).

    ``table`` is the learner's ``int64[K, N]`` plan over the blueprint's states (``model.tab``), episode ``i`` starts
    from row ``rows[i]``; ``loc`` maps the twin's grid cells to believed blueprint cells
    (:func:`~dtradar_rl.tabular.fingerprints.localisation`); ``sensed`` / ``expected`` are the twin's and the
    blueprint's :func:`radio_flags`; ``starts`` and ``targets`` are grid cells of the twin. Returns what
    :func:`~dtradar_rl.tabular.evaluation.follow` returns, plus ``returns`` (each episode's discounted return on
    the twin) and ``replans`` (the episode's re-plans). With a ``tracker`` the robot carries its belief along its own
    moves (:class:`~dtradar_rl.tabular.fingerprints.Tracker`) instead of reading ``loc`` afresh at every step."""
    cfg = (cfg or BatchConfig()).validate()
    plan_cfg = replace(cfg, tol=max(cfg.tol, REPLAN_TOL))
    max_steps = int(max_steps or twin.mdp.max_steps)
    starts, targets = np.asarray(starts, np.int64), np.asarray(targets, np.int64)
    ep = _start(model, table, rows, twin, loc, starts, targets, tracker)
    for _ in range(max_steps):
        live = np.flatnonzero(~ep.done)
        if not live.size:
            break
        # 1. localise (the module docstring's steps)
        cell = twin.cells[ep.s[live]]
        b_cell = ep.belief[live] if tracker is not None else loc[cell]
        b = model.tab.state_of[b_cell]
        # 2. sense, 3. re-plan, then move
        _sense(ep, live, cell, b_cell, b, sensed, expected)
        _replan(ep, live, name, model, plan_cfg)
        a, st, nxt = _move(ep, live, b, twin, cfg.gamma)
        if tracker is not None:
            _track(ep, live, tracker, twin, b_cell, a, st, nxt)
    return _paths(ep, twin, starts)


@dataclass
class _Episodes:
    """What the lockstep episodes carry from one step to the next (one entry per episode unless said)."""

    s: np.ndarray  # the twin's state the robot stands on
    t: np.ndarray  # the twin's state of its target
    targets: np.ndarray  # the grid cell of its target
    plan: np.ndarray  # int64[n_ep, N] the move it makes from every believed blueprint state
    forbid: np.ndarray  # bool[n_ep, N, 4] the moves it believes blocked, in believed coordinates
    dirty: np.ndarray  # its forbidden set grew since its plan was made
    nb: np.ndarray  # the blueprint's neighbour_cells
    utargets: np.ndarray  # the distinct targets
    r_twin: np.ndarray  # [U, N_twin, 4] the twin's reward towards each distinct target
    urow: np.ndarray  # the row of its target in utargets and r_twin
    done: np.ndarray
    steps: np.ndarray
    travelled: np.ndarray
    collisions: np.ndarray
    replans: np.ndarray
    returns: np.ndarray
    disc: np.ndarray  # gamma ** steps, the discount of its next reward
    belief: np.ndarray  # its believed blueprint cell (read with a tracker only)


def _start(
    model: EmpiricalModel,
    table: np.ndarray,
    rows: np.ndarray,
    twin: TabularMDP,
    loc: np.ndarray,
    starts: np.ndarray,
    targets: np.ndarray,
    tracker: Tracker | None,
) -> _Episodes:
    """Every episode on its start, following its row of ``table``, nothing forbidden yet, believing where the nearest
    fingerprint (or the tracker's start) puts it."""
    bp = model.tab
    n_ep = starts.size
    s, t = twin.states(starts).copy(), twin.states(targets)
    plan = np.asarray(table)[np.asarray(rows)].copy()
    forbid = np.zeros((n_ep, bp.n, 4), bool)
    dirty = np.zeros(n_ep, bool)
    nb = neighbour_cells(bp.mdp)
    utargets = np.unique(targets)
    r_twin, _ = twin.rewards(model.reward, twin.states(utargets))  # [U, N_twin, 4]
    urow = np.searchsorted(utargets, targets)
    done = s == t
    steps = np.zeros(n_ep, np.int64)
    travelled = np.zeros(n_ep, np.int64)
    collisions = np.zeros(n_ep, np.int64)
    replans = np.zeros(n_ep, np.int64)
    returns = np.zeros(n_ep)
    disc = np.ones(n_ep)
    belief = (tracker.start if tracker is not None else loc.__getitem__)(twin.cells[s])
    return _Episodes(
        s, t, targets, plan, forbid, dirty, nb, utargets, r_twin, urow, done, steps, travelled, collisions, replans,
        returns, disc, belief,
    )  # fmt: skip


def _sense(
    ep: _Episodes,
    live: np.ndarray,
    cell: np.ndarray,
    b_cell: np.ndarray,
    b: np.ndarray,
    sensed: np.ndarray,
    expected: np.ndarray,
) -> None:
    """Forbid the moves towards a neighbour the blueprint says has radio but that senses none (not the target)."""
    # what the robot senses next to it, against what the blueprint says is next to where it believes it is
    true_nb, believed_nb = ep.nb[cell], ep.nb[b_cell]
    flag = np.where(true_nb >= 0, sensed[true_nb.clip(0)], False)
    expect = np.where(believed_nb >= 0, expected[believed_nb.clip(0)], False)
    new = ~flag & expect & (believed_nb != ep.targets[live, None]) & ~ep.forbid[live, b]
    li, la = np.nonzero(new)
    ep.forbid[live[li], b[li], la] = True
    ep.dirty[live[li]] = True


def _replan(ep: _Episodes, live: np.ndarray, name: str, model: EmpiricalModel, plan_cfg: BatchConfig) -> None:
    """Solve the learner again, all together, for the robots whose forbidden set grew."""
    again = live[ep.dirty[live]]
    if again.size:
        ep.plan[again] = learn(name, model, ep.targets[again], plan_cfg, forbidden=ep.forbid[again])
        ep.dirty[again] = False
        ep.replans[again] += 1


def _move(
    ep: _Episodes, live: np.ndarray, b: np.ndarray, twin: TabularMDP, gamma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Make each live robot's planned move on the twin and tally it; returns the moves, the states they started
    from and the states they led to."""
    a = ep.plan[live, b]
    st = ep.s[live]
    nxt = twin.next[st, a]
    bump = twin.collides[st, a]
    ep.returns[live] += ep.disc[live] * ep.r_twin[ep.urow[live], st, a]
    ep.disc[live] *= gamma
    ep.travelled[live] += nxt != st
    ep.collisions[live] += bump
    ep.steps[live] += 1
    # a bump is a move the robot now knows is blocked: forbidden, and a new plan before the next move
    ep.forbid[live[bump], b[bump], a[bump]] = True
    ep.dirty[live[bump]] = True
    ep.s[live] = nxt
    ep.done[live] = nxt == ep.t[live]
    return a, st, nxt


def _track(
    ep: _Episodes,
    live: np.ndarray,
    tracker: Tracker,
    twin: TabularMDP,
    b_cell: np.ndarray,
    a: np.ndarray,
    st: np.ndarray,
    nxt: np.ndarray,
) -> None:
    """Carry each live robot's belief along the move it made."""
    b_new = tracker.step(b_cell, a, nxt != st, twin.cells[nxt])
    # believing to stand on the target while the episode goes on: the belief is wrong, start it afresh
    lost = (b_new == ep.targets[live]) & ~ep.done[live]
    ep.belief[live] = np.where(lost, tracker.start(twin.cells[nxt]), b_new)


def _paths(ep: _Episodes, twin: TabularMDP, starts: np.ndarray) -> dict[str, np.ndarray]:
    """What :func:`follow_sensing` returns: the episodes' outcomes and the shortest path of each."""
    shortest = twin.mdp.bfs_distances_many(ep.utargets)[ep.urow, starts]
    return {
        "success": ep.done,
        "steps": ep.steps,
        "travelled": ep.travelled,
        "shortest": shortest,
        "collisions": ep.collisions,
        "returns": ep.returns,
        "replans": ep.replans,
    }


__all__ = ["REPLAN_TOL", "SENSING", "SUFFIX", "WINDOW", "follow_sensing", "neighbour_cells", "radio_flags"]
