"""dtradar_rl: navigation agents on dtradar datasets (after DT-RaDaR, arXiv 2411.12284).

A per-cell table becomes a grid MDP (:mod:`dtradar_rl.task.mdp`); agents observe radio features by preset (:mod:`dtradar_rl.task.observations`)
through a gymnasium env (:mod:`dtradar_rl.envs.nav_env`) or a batched torch env (:mod:`dtradar_rl.envs.batched`); DQN (:mod:`dtradar_rl.train.dqn`) trains on the
blueprint twin and :mod:`dtradar_rl.evaluation.evaluate` measures success, SPL, collisions and latency on blueprint and dynamic twins.

    from dtradar_rl import config_for, train, load_policy, evaluate, load_dataset
    result = train(config_for("tuned", scene="synthetic"))
    metrics, rollouts = evaluate(load_policy(result.checkpoint), load_dataset("synthetic/dynamic"))

Never imports Sionna.
"""

from __future__ import annotations

_EXPORTS = {
    "GridMDP": ".mdp", "ACTIONS": ".mdp", "REWARDS": ".mdp",
    "OBS_PRESETS": ".observations", "Normalizer": ".observations", "build_observations": ".observations",
    "DtradarNavEnv": ".envs", "register_dataset_envs": ".envs",
    "BatchedNavEnv": ".batched",
    "DQNConfig": ".config", "config_for": ".config", "PRESETS": ".config", "train": ".dqn",
    "Policy": ".policy", "load_policy": ".policy", "OfflineConfig": ".offline", "train_offline": ".offline",
    "evaluate": ".evaluate", "spl": ".evaluate", "cross_matrix": ".evaluate",
    "load_dataset": ".data",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name], __name__), name)
    raise AttributeError(f"module 'dtradar_rl' has no attribute {name!r}")
