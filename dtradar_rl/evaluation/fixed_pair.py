"""Inference of a fixed-pair agent (the paper's protocol) on its pair, on the twin it trained on or another one.

An agent trained with ``--pair paper`` (or ``--start/--target``) has no target in its state, so random pairs say
nothing about it; what the paper reports is whether, and in how many steps, it reaches *its* pair (Table VI,
Figs. 10 and 22-24). The pair is the one recorded in the checkpoint; on another twin (the dynamic one) an end that
became blocked, or cut off, is snapped to the nearest cell of the largest free region there
(:mod:`dtradar_rl.task.pairs`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import Rollouts, path_length, rollout
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.pairs import ResolvedPair, resolve, training_pair


def policy_pair(policy: Policy, ds: Dataset) -> ResolvedPair | None:
    """The fixed pair of ``policy`` placed on ``ds``, or ``None`` for a goal-conditioned (random-pair) policy."""
    cfg = policy.config
    if not getattr(cfg, "fixed_pair", False):
        return None
    recorded = policy.meta.get("stats", {}).get("pair")
    if recorded is None:  # a checkpoint from before pairs were recorded: resolve as training did
        return training_pair(cfg, ds)
    mdp = GridMDP.from_dataset(ds)
    s, t = tuple(recorded["start"]), tuple(recorded["target"])
    ok = all(0 <= c[0] < mdp.nx and 0 <= c[1] < mdp.ny and not mdp.blocked[c[1], c[0]] for c in (s, t))
    if ok and mdp.connected(mdp.cell(*s), mdp.cell(*t)):
        return resolve(mdp, ds.grid_info, cfg.scene, s, t)
    from dtradar_rl.task.pairs import (
        snap,  # the twin moved an obstacle onto an end: the nearest usable cell instead
    )

    (s2, _), (t2, _) = snap(mdp, *s), snap(mdp, *t)
    return resolve(mdp, ds.grid_info, cfg.scene, s2, t2)


def evaluate_pair(
    policy: Policy, ds: Dataset, *, max_steps: int | None = None, device: str = "cpu"
) -> tuple[dict[str, Any], ResolvedPair, Rollouts]:
    """One greedy episode of a fixed-pair policy on its pair on ``ds`` (capped like training: 10x the shortest
    path unless ``max_steps``). Returns a results row (the columns of
    :func:`~dtradar_rl.evaluation.evaluate.markdown_table` plus the pair), the pair and the rollout."""
    pair = policy_pair(policy, ds)
    if pair is None:
        raise ValueError("evaluate_pair needs a policy trained on a fixed pair (--pair paper or --start/--target)")
    cells = np.array([pair.cells(ds.shape[1])])
    roll = rollout(policy, ds, cells, max_steps=max_steps or pair.cap, device=device)
    travelled = path_length(roll.paths[0])
    success = bool(roll.success[0])
    row = {
        "case": f"{policy.meta['dataset']['name']} -> {ds.name} (pair {pair.start} -> {pair.target})",
        "dataset": ds.name,
        "version": ds.version,
        "shield": False,
        "pairs": 1,
        "success_rate": float(success),
        "spl": float(success) * pair.shortest / max(travelled, pair.shortest, 1),
        "collisions": float(roll.collisions[0]),
        "steps": float(roll.steps[0]),
        "path_length": float(travelled),
        "shortest": float(pair.shortest),
        "latency_ms": None,
        "pair": pair.to_dict(),
    }
    return row, pair, roll


__all__ = ["policy_pair", "evaluate_pair"]
