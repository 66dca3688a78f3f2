"""dtradar_rl: navigation agents on dtradar datasets (after DT-RaDaR, arXiv 2411.12284).

Role folders, each importing only the ones before it: :mod:`~dtradar_rl.task` (a per-cell table as a grid MDP,
observations, pairs, the base config) → :mod:`~dtradar_rl.envs` (gymnasium and batched torch envs) and
:mod:`~dtradar_rl.viz` → :mod:`~dtradar_rl.agents` (Q-network, ``Policy``, planner) → :mod:`~dtradar_rl.train`
(DQN) → :mod:`~dtradar_rl.evaluation` (success, SPL, collisions, latency on blueprint and dynamic twins) →
:mod:`~dtradar_rl.offline` (logged datasets, d3rlpy) → :mod:`~dtradar_rl.experiments` (paper, sweeps, benchmarks)
→ :mod:`~dtradar_rl.cli`.

    from dtradar_rl import config_for, train, load_policy, evaluate, load_dataset
    result = train(config_for("tuned", scene="synthetic"))
    metrics, rollouts = evaluate(load_policy(result.checkpoint), load_dataset("synthetic/dynamic"))

Importing it registers the gymnasium ids of every built twin (:mod:`dtradar_rl.envs.registration`), as gymnasium's
own packages do: ``import dtradar_rl; gym.make("dtradar/cubicle-blueprint-v0")`` is the default agent's honest
observation. Never imports Sionna.
"""

from __future__ import annotations

_EXPORTS = {
    "GridMDP": "dtradar_rl.task.grid_mdp",
    "MovingGridMDP": "dtradar_rl.task.grid_mdp",
    "ACTIONS": "dtradar_rl.task.grid_mdp",
    "REWARDS": "dtradar_rl.task.rewards",
    "OBS_PRESETS": "dtradar_rl.task.observations",
    "Normalizer": "dtradar_rl.task.observations",
    "build_observations": "dtradar_rl.task.observations",
    "load_dataset": "dtradar_rl.task.twins",
    "DtradarNavEnv": "dtradar_rl.envs.nav_env",
    "register_dataset_envs": "dtradar_rl.envs.registration",
    "BatchedNavEnv": "dtradar_rl.envs.batched",
    "Policy": "dtradar_rl.agents.policy",
    "DQNConfig": "dtradar_rl.train.config",
    "config_for": "dtradar_rl.train.config",
    "PRESETS": "dtradar_rl.train.config",
    "train": "dtradar_rl.train.dqn",
    "load_policy": "dtradar_rl.train.saved_runs",
    "evaluate": "dtradar_rl.evaluation.evaluate",
    "spl": "dtradar_rl.evaluation.evaluate",
    "cross_matrix": "dtradar_rl.evaluation.evaluate",
    "OfflineConfig": "dtradar_rl.offline.config",
    "train_offline": "dtradar_rl.offline.trainer",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'dtradar_rl' has no attribute {name!r}")


import dtradar_rl.envs  # noqa: E402, F401  (registers the gymnasium ids; the env classes load when first used)
