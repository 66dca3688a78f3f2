"""Exact evaluation of table policies: their value for every (cell, target), and their paths from given starts.

A policy given as a table (target, cell) -> move, or -> move probabilities, is evaluated exactly on a static twin:
``V^π(s) = Σ_a π(a | s, t) · (r(s, a, t) + γ · [s' != t] · V^π(s'))`` by sweeps until no value moves by more than
the solver's relative tolerance (:data:`~dtradar_rl.tabular.solver.TOL`), the same stopping rule as V*. This covers
the memoryless learned agents through their greedy table (:func:`greedy_table`: a memoryless agent on a twin without
measurement noise sees a function of (cell, target), so it *is* a table); agents with memory keep rollouts.

A deterministic table's episodes are followed move by move (:func:`follow`) for success and SPL with the same
definitions as the rollouts of :mod:`dtradar_rl.evaluation.evaluate` (a collision travels nothing; an episode is cut
at the step limit). Values are infinite-horizon discounted returns: a rollout cut at ``max_steps`` differs from them
by at most ``γ^max_steps`` times the largest value (below 1e-10 of it at γ = 0.9 on every built-in twin).
"""

from __future__ import annotations

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.tabular.memory import check_memory, chunk_work
from dtradar_rl.tabular.solver import TabularMDP, check_gamma, check_size, chunk_size, expectation_sweeps

#: Observations per forward pass of :func:`greedy_table`.
GREEDY_BATCH = 65_536


def _check_table(policy: np.ndarray, k: int, n: int) -> tuple[np.ndarray, bool]:
    policy = np.asarray(policy)
    deterministic = policy.ndim == 2
    if policy.shape[:2] != (k, n) or (not deterministic and policy.shape != (k, n, 4)):
        raise InvalidSettingError(
            f"a table policy for {k} targets x {n} cells must be int[{k}, {n}] moves or float[{k}, {n}, 4] "
            f"probabilities, got shape {policy.shape}",
            hint="index it [target row, state] in TabularMDP.cells order",
        )
    if deterministic and ((policy < 0) | (policy > 3)).any():
        raise InvalidSettingError("a table policy's moves must be 0..3", hint="0: X-, 1: X+, 2: Y-, 3: Y+")
    if not deterministic:
        bad = ~np.isfinite(policy).all(-1) | (policy < 0).any(-1) | (np.abs(policy.sum(-1) - 1) > 1e-6)
        if bad.any():
            raise InvalidSettingError(
                "a table policy's move probabilities must be finite, >= 0 and sum to 1 in every (target, cell)",
                hint=f"{int(bad.sum())} rows do not; normalise them",
            )
    return policy, deterministic


def policy_values(
    tab: TabularMDP,
    policy: np.ndarray,
    targets: np.ndarray,
    reward: str = "geodesic",
    gamma: float = 0.9,
) -> np.ndarray:
    """``float64[K, N]`` the exact value of a table ``policy`` (``int[K, N]`` moves or ``float[K, N, 4]``
    probabilities, rows in ``targets`` order, states in ``tab.cells`` order) for every start state."""
    targets = np.asarray(targets, np.int64)
    gamma = check_gamma(gamma)
    check_size(targets.size, tab.n, "evaluation")
    k, n = targets.size, tab.n
    parts = {f"the values (float64, {k:,} targets x {n:,} cells)": 8 * k * n}
    if np.ndim(policy) == 3:  # checking a probability table: one bool per (target, cell, move) at a time
        parts["checking its move probabilities"] = 4 * k * n
    parts[f"one chunk of {min(k, chunk_size(n)):,} targets' working arrays"] = chunk_work(k, n)
    check_memory("the exact evaluation of a table policy", parts, hint="evaluate fewer targets at a time")
    policy, deterministic = _check_table(policy, targets.size, tab.n)
    t_states = tab.states(targets)
    out = np.empty((targets.size, tab.n))
    k = chunk_size(tab.n)
    for i in range(0, targets.size, k):
        r, reached = tab.rewards(reward, t_states[i : i + k])
        p = policy[i : i + k]
        w = np.eye(4)[p] if deterministic else np.asarray(p, np.float64)  # [k, N, 4]
        v, _, _ = expectation_sweeps(r, reached, tab.next, gamma, w)
        out[i : i + k] = v
    return out


def uniform_values(tab: TabularMDP, targets: np.ndarray, reward: str = "geodesic", gamma: float = 0.9) -> np.ndarray:
    """The exact value of uniformly random moves (the normalised scores' 0)."""
    targets = np.asarray(targets, np.int64)
    uniform = np.broadcast_to(0.25, (targets.size, tab.n, 4))  # a view: each chunk is made as it is evaluated
    return policy_values(tab, uniform, targets, reward, gamma)


def follow(
    tab: TabularMDP, actions: np.ndarray, rows: np.ndarray, starts: np.ndarray, targets: np.ndarray, max_steps: int
) -> dict[str, np.ndarray]:
    """Follow a deterministic table from every start: ``success``, ``steps``, ``travelled`` (moves that changed
    cell), ``collisions`` and ``shortest`` (breadth-first) per episode: what a rollout in the env gives for a
    deterministic policy on a static twin without measurement noise. ``actions`` is ``int[K, N]``; episode ``i``
    uses row ``rows[i]``, starts and targets are grid cells."""
    s = tab.states(starts).copy()
    t = tab.states(targets)
    n = s.size
    done = s == t
    steps = np.zeros(n, np.int64)
    travelled = np.zeros(n, np.int64)
    collisions = np.zeros(n, np.int64)
    for _ in range(max_steps):
        live = ~done
        if not live.any():
            break
        a = actions[rows[live], s[live]]
        nxt = tab.next[s[live], a]
        travelled[live] += nxt != s[live]
        collisions[live] += tab.collides[s[live], a]
        steps[live] += 1
        s[live] = nxt
        done[live] = nxt == t[live]
    d = tab.mdp.bfs_distances_many(np.unique(targets))
    order = np.searchsorted(np.unique(targets), targets)
    shortest = d[order, starts]
    return {"success": done, "steps": steps, "travelled": travelled, "shortest": shortest, "collisions": collisions}


def path_metrics(paths: dict[str, np.ndarray]) -> dict[str, float]:
    """Success rate and SPL of :func:`follow`'s episodes, as :func:`~dtradar_rl.evaluation.evaluate.spl` has it."""
    s = paths["success"].astype(np.float64)
    lo = paths["shortest"].astype(np.float64)
    p = paths["travelled"].astype(np.float64)
    ratio = np.where(np.maximum(p, lo) > 0, lo / np.maximum(np.maximum(p, lo), 1e-12), 1.0)
    out = {"success_rate": float(s.mean()), "spl": float((s * ratio).mean()), "steps": float(paths["steps"].mean())}
    if "collisions" in paths:
        out["collisions"] = float(paths["collisions"].mean())
    return out


def greedy_table(policy, ds: Dataset, tab: TabularMDP, targets: np.ndarray, device: str = "cpu") -> np.ndarray:
    """``int64[K, N]`` the greedy move of a memoryless :class:`~dtradar_rl.agents.policy.Policy` (a Q-network or a
    d3rlpy agent, anything with ``observations(ds)`` and ``act(obs)``) in every (target, cell) of ``ds``: its
    observation there, built by the same lookup the envs use, through its own ``act``."""
    if getattr(getattr(policy, "config", None), "memory_radius", 0):
        raise InvalidSettingError(
            "a memory agent's move depends on what it has sensed so far, not on (cell, target) alone",
            hint="evaluate memory agents by rollouts (dtradar_rl.evaluation.evaluate)",
        )
    table = policy.observations(ds)
    if getattr(table, "snapshots", 1) != 1:
        raise InvalidSettingError(f"{ds.name} is a moving twin", hint="greedy tables are for static twins")
    targets = np.asarray(targets, np.int64)
    cell_part = torch.as_tensor(table.cell_part[tab.cells])
    out = np.empty((targets.size, tab.n), np.int64)
    per_call = max(1, GREEDY_BATCH // max(1, tab.n))  # targets per forward pass
    for i in range(0, targets.size, per_call):
        rows = targets[i : i + per_call]
        tp = torch.as_tensor(table.target_part[rows])  # [k, Dt]
        obs = torch.cat([cell_part.repeat(rows.size, 1), tp.repeat_interleave(tab.n, 0)], 1)
        with torch.no_grad():
            out[i : i + rows.size] = policy.act(obs.to(device)).cpu().numpy().reshape(rows.size, tab.n)
    return out


__all__ = ["follow", "greedy_table", "path_metrics", "policy_values", "uniform_values"]
