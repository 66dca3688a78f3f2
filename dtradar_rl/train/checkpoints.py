"""Loading a DQN checkpoint back as a greedy :class:`~dtradar_rl.agents.policy.Policy` with its
:class:`~dtradar_rl.train.config.DQNConfig`."""

from __future__ import annotations

import json
from pathlib import Path

from dtradar_rl.agents.checkpoints import CHECKPOINT_FORMAT, CheckpointError, read_checkpoint
from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.train.config import DQNConfig


def load_policy(path: str | Path, device: str = "cpu") -> Policy:
    """The greedy DQN policy saved at ``path`` (a ``model.pt``)."""
    state = read_checkpoint(path, (CHECKPOINT_FORMAT,), what="dtradar DQN checkpoint (model.pt)", device=device)
    try:
        arch = state["arch"]
        q = QNetwork(arch["in_dim"], tuple(arch["hidden"]), arch["n_actions"]).to(device)
        q.load_state_dict(state["q"])
        cfg = DQNConfig.from_dict(json.loads(state["config"]))
        normalizer = Normalizer.from_dict(state["normalizer"])
        preset = state["obs"]["preset"]
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        raise CheckpointError(
            f"{path} is a DQN checkpoint with missing or inconsistent parts ({e})",
            hint="train again; a checkpoint edited by hand cannot be repaired",
        ) from e
    q.eval()
    return Policy(
        q,
        cfg,
        normalizer,
        preset,
        {"dataset": state.get("dataset"), "stats": state.get("stats", {}), "path": str(path)},
    )
