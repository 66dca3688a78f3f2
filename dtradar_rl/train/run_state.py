"""The state of a DQN run while it trains (:class:`RunState`: the twin and env, the networks, the optimiser, the
replay buffer, the random streams, the counters and the episodes) and its round trip through ``last.pt``
(:func:`save_training_state`, :func:`restore_training_state`), kept side by side so that what is saved and what a
resumed run reads back stay the same keys.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.checkpoints import (
    CHECKPOINT_FORMAT,
    TRAINING_STATE,
    CheckpointError,
    save_torch_atomic,
    twin_record,
)
from dtradar_rl.agents.policy import QNetwork
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.pairs import ResolvedPair
from dtradar_rl.train.config import DQNConfig
from dtradar_rl.train.replay import ReplayBuffer


@dataclass
class RunState:
    """What one training holds while it runs: its twin and environment, the networks and their optimiser, the replay
    buffer and the exploration stream, the counters and the episodes finished so far."""

    cfg: DQNConfig
    #: the run folder (``cfg.out_dir``)
    out: Path
    ds: Dataset
    normalizer: Normalizer
    #: the fixed (start, target) pair of the paper's protocol, or None for random pairs
    pair: ResolvedPair | None
    env: BatchedNavEnv
    q: QNetwork
    q_target: QNetwork
    optimizer: torch.optim.Optimizer
    buffer: ReplayBuffer
    #: exploration and minibatch sampling (the env draws from its own generators)
    gen: torch.Generator
    #: the torch threads used and the ``--threads`` setting: the reproducibility record
    threads: dict[str, Any]
    device: torch.device
    ep_reward: torch.Tensor
    ep_collisions: torch.Tensor
    env_steps: int = 0
    updates: int = 0
    #: ``(episode, env_step, reward, steps, collisions, success)`` per finished episode
    episodes: list[tuple] = field(default_factory=list)

    def reset_where(self, mask: torch.Tensor) -> None:
        """New episodes for the robots in ``mask``: on random pairs, or all on the run's fixed pair."""
        if self.pair is None:
            self.env.reset_where(mask)
        else:
            k = int(mask.sum())
            start, target = self.pair.cells(self.ds.shape[1])
            self.env.reset_where(mask, starts=[start] * k, targets=[target] * k)


def save_training_state(run: RunState) -> None:
    """``last.pt``: everything :func:`restore_training_state` needs to continue the run exactly (the replay buffer with
    ``save_replay``)."""
    env = run.env
    state = {
        "format": CHECKPOINT_FORMAT,
        "kind": TRAINING_STATE,
        "config": json.dumps(run.cfg.to_dict()),
        "dataset": twin_record(run.ds),
        "stats": run.threads,
        "q": run.q.state_dict(),
        "q_target": run.q_target.state_dict(),
        "optimizer": run.optimizer.state_dict(),
        "env_steps": run.env_steps,
        "updates": run.updates,
        "episodes": run.episodes,
        "gen": run.gen.get_state(),
        "env_gen": env.gen.get_state(),
        "env_noise_gen": env.noise_gen.get_state(),
        "env": {k: getattr(env, k) for k in env.state_keys},
        "ep_reward": run.ep_reward,
        "ep_collisions": run.ep_collisions,
        "normalizer": run.normalizer.to_dict(),
    }
    if run.cfg.save_replay:
        state["replay"] = run.buffer.state_dict()
    save_torch_atomic(state, run.out / "last.pt")


def restore_training_state(run: RunState, state: dict[str, Any]) -> None:
    """Continue ``run`` where ``last.pt`` (``state``) stopped: networks, optimiser, buffer, counters, episodes, the
    random streams and every robot's episode."""
    env, device = run.env, run.device
    try:
        run.q.load_state_dict(state["q"])
        run.q_target.load_state_dict(state["q_target"])
        run.optimizer.load_state_dict(state["optimizer"])
        if "replay" in state:
            run.buffer.load_state_dict(state["replay"])
        run.env_steps, run.updates = state["env_steps"], state["updates"]
        run.episodes = [tuple(e) for e in state["episodes"]]
        run.gen.set_state(state["gen"].cpu())
        env.gen.set_state(state["env_gen"].cpu())
        if "env_noise_gen" in state:
            env.noise_gen.set_state(state["env_noise_gen"].cpu())
        for k in env.state_keys:
            setattr(env, k, state["env"][k].to(device))
        run.ep_reward, run.ep_collisions = state["ep_reward"].to(device), state["ep_collisions"].to(device)
    except (KeyError, TypeError, ValueError, RuntimeError) as e:  # the family check lets none of these through
        raise CheckpointError(
            f"{run.out / 'last.pt'} does not fit this run ({type(e).__name__}: {e})",
            hint=f"pick another --out, or train again without --resume (it replaces the run in {run.out})",
        ) from e
    if run.cfg.verbose:
        print(f"resumed from {run.out / 'last.pt'} at {run.env_steps} env steps, {run.updates} updates")
