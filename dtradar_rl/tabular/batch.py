"""Tabular batch RL on a logged dataset, and the dataset's ceiling: the best any policy could learn from it.

A logged dataset (:mod:`dtradar_data.store.logged`) is turned into an **empirical model**: for every (cell, action)
the number of times it was logged, ``n(s, a)``, and the cell it led to (the next step's cell in the same episode; the
target when the step ended the episode by reaching it; a step cut by truncation tells nothing). Moves on a twin are
deterministic, so one visit shows a (cell, action) exactly; the model is checked to never see two successors. What
the model does not know is every (cell, action) that was never logged. The reward is the twin's documented reward
function of (cell, action, target) (:func:`~dtradar_rl.task.rewards.reward_fn`), known for *every* target: a transition
logged for one target teaches the move for all of them, the hindsight relabelling of goal-conditioned RL, exact here.

The learners (one file, read top to bottom; the settings in :class:`BatchConfig`), solved for many targets at once:

- ``ce``, **certainty equivalence** ("RL on the empirical MDP", the baseline of SPIBB, Laroche et al. 2019): value
  iteration on the model, an unseen (cell, action) keeping its initial value 0, as a table-based learner would;
- ``lcb``, **pessimistic value iteration** with a count penalty (VI-LCB, Rashidinejad et al. 2021; the
  reward-adjusted MDP of Laroche et al.): ``r - β / sqrt(n(s, a))`` on logged pairs, unseen pairs not allowed;
- ``spibb``, **Π_b-SPIBB** (Laroche et al. 2019): policy iteration in which every move logged fewer than ``N∧``
  times keeps the behaviour's probability, estimated from counts ``n(s, a) / n(s)``, and the rest of the mass goes
  to the best well-logged move; a stochastic table.

And the **ceiling**: the best a policy can do using only the (cell, action) pairs the data contains, on the twin it
was logged on with the true cell: SPL of the shortest path through logged moves only (breadth-first on the directed
graph of logged moves), and the optimal return restricted to logged moves. No learner that stays inside the data can
beat it; a learner above it has generalised beyond the data (a network can, from the radio features).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from dtradar_data.core.errors import CorruptDatasetError, InvalidSettingError, unknown_name
from dtradar_data.store.logged import LoggedDataset, parse_logged_id
from dtradar_rl.tabular.memory import check_memory, chunk_work
from dtradar_rl.tabular.solver import (
    GAMMA,
    TOL,
    TabularMDP,
    bellman_sweeps,
    check_gamma,
    chunk_size,
    expectation_sweeps,
)

LEARNERS: tuple[str, ...] = ("ce", "lcb", "spibb")
NAMES = {"ce": "CE", "lcb": "VI-LCB", "spibb": "Π_b-SPIBB", "ceiling": "data ceiling"}


@dataclass(frozen=True)
class BatchConfig:
    """Settings of the tabular batch learners (docs, Tabular RL, says which were measured)."""

    gamma: float = GAMMA
    """discount of the learners' values"""
    lcb_beta: float = 0.1
    """VI-LCB: the count penalty β / sqrt(n(s, a)), in reward units (not tuned)"""
    spibb_n_wedge: int = 1
    """Π_b-SPIBB: moves logged fewer times than this keep the behaviour's probability. Measured on Dallas Q3
    (expert / medium data, blueprint score): 1 gives 97.4 / 91.0, 2 gives 94.8 / 87.2, 5 gives 76.9 / -: moves are
    deterministic, so one visit shows a move exactly and keeping the (target-blind) behaviour elsewhere only costs"""
    spibb_iterations: int = 50
    """Π_b-SPIBB: most policy-iteration steps (it stops when the policy no longer changes)"""
    tol: float = TOL
    """CE and VI-LCB: value iteration stops at this relative change (the exact solution's 1e-12 by default; a
    sensing robot re-plans with a looser one, dtradar_rl.tabular.sensing)"""

    def validate(self) -> BatchConfig:
        check_gamma(self.gamma)
        if not (np.isfinite(self.lcb_beta) and self.lcb_beta >= 0):
            raise InvalidSettingError(f"lcb_beta must be finite and >= 0, got {self.lcb_beta}", hint="e.g. 0.1")
        if not (np.isfinite(self.tol) and 0 < self.tol < 1):
            raise InvalidSettingError(f"tol must be in (0, 1), got {self.tol}", hint="e.g. 1e-12 (exact) or 1e-6")
        if self.spibb_n_wedge < 1 or self.spibb_iterations < 1:
            raise InvalidSettingError("spibb_n_wedge and spibb_iterations must be >= 1", hint="e.g. 5 and 50")
        return self


@dataclass(frozen=True)
class EmpiricalModel:
    """What a logged dataset shows of a twin's moves (module docstring)."""

    tab: TabularMDP
    #: ``int64[N, 4]`` how often each (state, move) was logged
    counts: np.ndarray
    #: ``int64[N, 4]`` the state each logged move led to (-1 where never seen to end anywhere)
    successor: np.ndarray
    reward: str

    @property
    def seen(self) -> np.ndarray:
        return self.successor >= 0

    @property
    def behaviour(self) -> np.ndarray:
        """``float64[N, 4]`` the behaviour's move probabilities from counts (uniform where a cell was never logged)."""
        n = self.counts.sum(1, keepdims=True)
        return np.where(n > 0, self.counts / np.maximum(n, 1), 0.25)

    def coverage(self) -> dict[str, float]:
        return {
            "cells_visited": int((self.counts.sum(1) > 0).sum()),
            "cells": int(self.tab.n),
            "pairs_seen": int(self.seen.sum()),
            "pairs": int(self.tab.n * 4),
        }


def _check_same_grid(logged: LoggedDataset, tab: TabularMDP, cells: np.ndarray) -> None:
    """:class:`InvalidSettingError` naming both when ``logged`` was logged on another scene than ``tab``'s twin (its
    cell numbers are another grid's), or logs a cell outside ``tab``'s grid (a hand-made twin has no scene name)."""
    parent = parse_logged_id(logged.name).parent
    scene = parent.split("/")[0]
    twin = tab.mdp.name.partition("@")[0].split("/")
    h, w = tab.mdp.blocked.shape
    fix = (
        f"build the model on the twin the data was logged on, TabularMDP.from_dataset(load_dataset({parent!r})); or "
        f"log on this twin's scene: python -m dtradar_rl log --scene {twin[0] if len(twin) == 2 else '<scene>'}"
    )
    if len(twin) == 2 and twin[0] != scene:
        raise InvalidSettingError(
            f"{logged.name} was logged on {parent}, a twin of {scene}; {tab.mdp.name} is a twin of {twin[0]}: a log's "
            "cells are its own scene's grid cells",
            hint=fix,
        )
    outside = cells[(cells < 0) | (cells >= h * w)]
    if outside.size:
        raise InvalidSettingError(
            f"{logged.name} (logged on {parent}) logs cell {int(outside[0])}, outside the grid of "
            f"{tab.mdp.name!r}, {w} x {h} cells",
            hint=fix,
        )


def empirical_model(logged: LoggedDataset, tab: TabularMDP) -> EmpiricalModel:
    """The counts and successors of ``logged`` on ``tab``'s twin (:class:`InvalidSettingError` when the log is of
    another scene or grid; :class:`CorruptDatasetError` when a logged move contradicts itself or leaves the twin's
    free cells)."""
    a = logged.arrays()
    cell, action, episode = a["cell"].astype(np.int64), a["action"].astype(np.int64), a["episode"]
    _check_same_grid(logged, tab, np.concatenate([cell, a["target"].astype(np.int64)]))
    if (tab.state_of[cell] < 0).any():
        raise CorruptDatasetError(
            f"{logged.name} logs steps on cells that are blocked in {tab.mdp.name}",
            hint="train on the twin the data was logged on",
        )
    s = tab.state_of[cell]
    nxt = np.full(s.size, -1, np.int64)
    same = episode[1:] == episode[:-1]
    nxt[:-1][same] = s[1:][same]
    ends = a["terminated"].astype(bool)
    nxt[ends] = tab.state_of[a["target"].astype(np.int64)[ends]]
    counts = np.zeros((tab.n, 4), np.int64)
    np.add.at(counts, (s, action), 1)
    successor = np.full((tab.n, 4), -1, np.int64)
    known = nxt >= 0
    successor[s[known], action[known]] = nxt[known]
    clash = known & (successor[s, action] != nxt)
    if clash.any():
        raise CorruptDatasetError(
            f"{logged.name}: one (cell, move) led to two different cells, on a twin whose moves are deterministic",
            hint="the log does not belong to this twin (or is damaged): python -m dtradar_data verify " + logged.name,
        )
    seen = successor >= 0
    if (successor[seen] != tab.next[seen]).any():
        raise CorruptDatasetError(
            f"{logged.name}: a logged move led elsewhere than {tab.mdp.name}'s move does",
            hint="train on the twin the data was logged on",
        )
    reward = ((logged.meta.get("settings") or {}).get("reward")) or "geodesic"
    return EmpiricalModel(tab, counts, successor, reward)


# -- the learners -----------------------------------------------------------------------------------------------------
def _chunks(targets: np.ndarray, n: int):
    k = chunk_size(n)
    for i in range(0, targets.size, k):
        yield i, targets[i : i + k]


def certainty_equivalence(
    model: EmpiricalModel, targets: np.ndarray, cfg: BatchConfig, forbidden: np.ndarray | None = None
) -> np.ndarray:
    """``int64[K, N]`` greedy moves of value iteration on the empirical MDP (unseen moves keep the value 0);
    ``forbidden`` (``bool[K, N, 4]``, rows in targets order) removes moves known to be blocked."""
    tab, out = model.tab, np.empty((targets.size, model.tab.n), np.int64)
    for i, t in _chunks(targets, tab.n):
        f = None if forbidden is None else forbidden[i : i + t.size]
        r, reached = tab.rewards(model.reward, tab.states(t))
        v, _, _ = bellman_sweeps(
            r, reached, tab.next, cfg.gamma, allowed=model.seen, masked_value=0.0, forbidden=f, tol=cfg.tol
        )
        q = r + cfg.gamma * ~reached * v[np.arange(t.size)[:, None, None], tab.next[None]]
        q = np.where(model.seen[None], q, 0.0)
        out[i : i + t.size] = (q if f is None else np.where(f, -np.inf, q)).argmax(-1)
    return out


def _restricted(
    model: EmpiricalModel,
    t: np.ndarray,
    gamma: float,
    penalty: np.ndarray | None,
    forbidden: np.ndarray | None = None,
    tol: float = TOL,
):
    """Values and greedy moves over logged moves only (``penalty`` subtracted from their rewards, ``forbidden``
    moves removed); a state with no logged move is worth standing still forever with the reward's lowest step."""
    tab = model.tab
    r, reached = tab.rewards(model.reward, tab.states(t))
    if penalty is not None:
        r = r - penalty[None]
    allowed = model.seen[None] if forbidden is None else model.seen[None] & ~forbidden
    floor = float(r.min()) / (1 - gamma)
    v, _, _ = bellman_sweeps(r, reached, tab.next, gamma, allowed=allowed, floor=floor, tol=tol)
    q = r + gamma * ~reached * v[np.arange(t.size)[:, None, None], tab.next[None]]
    return v, np.where(np.broadcast_to(allowed, q.shape), q, -np.inf).argmax(-1)


def lower_confidence_bound(
    model: EmpiricalModel, targets: np.ndarray, cfg: BatchConfig, forbidden: np.ndarray | None = None
) -> np.ndarray:
    """``int64[K, N]`` greedy moves of VI-LCB: logged moves only, each penalised by ``β / sqrt(n(s, a))``
    (``forbidden`` as in :func:`certainty_equivalence`)."""
    penalty = cfg.lcb_beta / np.sqrt(np.maximum(model.counts, 1))
    out = np.empty((targets.size, model.tab.n), np.int64)
    for i, t in _chunks(targets, model.tab.n):
        f = None if forbidden is None else forbidden[i : i + t.size]
        out[i : i + t.size] = _restricted(model, t, cfg.gamma, penalty, f, cfg.tol)[1]
    return out


def spibb(model: EmpiricalModel, targets: np.ndarray, cfg: BatchConfig) -> np.ndarray:
    """``float64[K, N, 4]`` the move probabilities of Π_b-SPIBB (module docstring)."""
    tab = model.tab
    pi_b = model.behaviour
    boot = model.counts < cfg.spibb_n_wedge  # bootstrapped: keep the behaviour's probability
    fixed = np.where(boot, pi_b, 0.0)
    free_mass = 1.0 - fixed.sum(1)  # what the improvement step may move
    any_free = (~boot).any(1)
    out = np.empty((targets.size, tab.n, 4))
    for i, t in _chunks(targets, tab.n):
        r, reached = tab.rewards(model.reward, tab.states(t))
        pi = np.broadcast_to(pi_b, r.shape).copy()
        v = np.zeros(r.shape[:2])
        rows = np.arange(t.size)[:, None, None]
        for _ in range(cfg.spibb_iterations):
            # modified policy iteration: a few evaluation sweeps from the last values, then improve; the loop ends
            # when the policy no longer changes, after which one full evaluation makes its values exact
            v, _, _ = expectation_sweeps(r, reached, tab.next, cfg.gamma, pi * model.seen[None], v0=v, max_sweeps=20)
            q = np.where(model.seen[None], r + cfg.gamma * ~reached * v[rows, tab.next[None]], 0.0)
            best = np.where(boot[None], -np.inf, q).argmax(-1)
            new = np.broadcast_to(fixed, r.shape).copy()
            mass = np.broadcast_to(free_mass[None, :, None], best[..., None].shape)
            np.put_along_axis(new, best[..., None], mass, -1)
            new = np.where(any_free[None, :, None], new, pi_b[None])
            if np.array_equal(new, pi):
                break
            pi = new
        out[i : i + t.size] = pi
    return out


def learn(
    name: str,
    model: EmpiricalModel,
    targets: np.ndarray,
    cfg: BatchConfig | None = None,
    forbidden: np.ndarray | None = None,
) -> np.ndarray:
    """The table of learner ``name`` (:data:`LEARNERS`) for ``targets`` (grid cells), rows in targets order;
    ``forbidden`` (``bool[K, N, 4]``) removes moves known to be blocked, row by row (CE and VI-LCB: what a robot that
    senses re-plans with, :mod:`dtradar_rl.tabular.sensing`)."""
    cfg = (cfg or BatchConfig()).validate()
    fns = {"ce": certainty_equivalence, "lcb": lower_confidence_bound, "spibb": spibb}
    if name not in fns:
        raise unknown_name("tabular batch learner", name, LEARNERS)
    targets = np.asarray(targets, np.int64)
    k, n = targets.size, model.tab.n
    table = f"its table ({'float64' if name == 'spibb' else 'int64'}, {k:,} targets x {n:,} cells"
    parts = {table + (" x 4)" if name == "spibb" else ")"): (32 if name == "spibb" else 8) * k * n}
    parts[f"one chunk of {min(k, chunk_size(n)):,} targets' working arrays"] = chunk_work(k, n)
    check_memory(f"the {NAMES[name]} learner", parts, hint="learn for fewer targets (e.g. the evaluation pairs')")
    if forbidden is None:
        return fns[name](model, targets, cfg)
    if name == "spibb":
        raise InvalidSettingError(
            "Π_b-SPIBB re-planned with forbidden moves is not built (its bootstrapped moves keep the behaviour's "
            "probabilities, which a blocked move would have to give up)",
            hint="re-plan with ce or lcb",
        )
    forbidden = np.asarray(forbidden, bool)
    if forbidden.shape != (targets.size, model.tab.n, 4):
        raise InvalidSettingError(
            f"forbidden must be bool[{targets.size}, {model.tab.n}, 4] (targets x states x moves), "
            f"got {forbidden.shape}",
            hint="index it [target row, state, move] in TabularMDP.cells order",
        )
    return fns[name](model, targets, cfg, forbidden)


# -- the ceiling ------------------------------------------------------------------------------------------------------
def ceiling(model: EmpiricalModel, pairs: np.ndarray, cfg: BatchConfig | None = None) -> dict[str, Any]:
    """The best any policy using only logged moves reaches on ``pairs`` (start, target grid cells) of the twin the
    data was logged on, with the true cell: per pair the SPL of the shortest path through logged moves within the
    step limit, and the optimal discounted return restricted to logged moves (``values``)."""
    cfg = (cfg or BatchConfig()).validate()
    tab = model.tab
    t0 = time.perf_counter()
    s_idx, a_idx = np.nonzero(model.seen & (tab.next != np.arange(tab.n)[:, None]))
    # reversed logged moves: a search from the target over them is the fewest logged moves from every cell
    graph = csr_matrix((np.ones(s_idx.size), (tab.next[s_idx, a_idx], s_idx)), shape=(tab.n, tab.n))
    targets = np.unique(pairs[:, 1])
    k, n = targets.size, tab.n
    parts = {f"its values and logged-move distances (float64, 2 x {k:,} targets x {n:,} cells)": 16 * k * n}
    parts[f"one chunk of {min(k, chunk_size(n)):,} targets' working arrays"] = chunk_work(k, n)
    check_memory("the data ceiling", parts, hint="measure it on fewer pairs' targets")
    t_states = tab.states(targets)
    d_logged = shortest_path(graph, method="D", directed=True, unweighted=True, indices=t_states)
    rows = np.searchsorted(targets, pairs[:, 1])
    lengths = d_logged[rows, tab.states(pairs[:, 0])]
    shortest = tab.mdp.bfs_distances_many(targets)[rows, pairs[:, 0]].astype(np.float64)
    ok = np.isfinite(lengths) & (lengths <= tab.mdp.max_steps)
    spl_pairs = np.where(ok, shortest / np.maximum(np.where(ok, lengths, 1.0), shortest), 0.0)
    values = np.empty((targets.size, tab.n))
    for i, t in _chunks(targets, tab.n):
        values[i : i + t.size] = _restricted(model, t, cfg.gamma, None)[0]
    return {
        "success_rate": float(ok.mean()),
        "spl": float(spl_pairs.mean()),
        "values": values,
        "targets": targets,
        "seconds": time.perf_counter() - t0,
    }


__all__ = [
    "LEARNERS",
    "NAMES",
    "BatchConfig",
    "EmpiricalModel",
    "ceiling",
    "certainty_equivalence",
    "empirical_model",
    "learn",
    "lower_confidence_bound",
    "spibb",
]
