"""Trained policies and their checkpoints: the Q-network, a greedy :class:`Policy`, saving and loading ``model.pt``.

A checkpoint is self-contained: weights, architecture, the training config, the observation preset and the feature
normaliser, so a policy observes any twin the way it was trained. The online DQN (:mod:`dtradar_rl.train.dqn`) writes
them; evaluation (:mod:`dtradar_rl.evaluation.evaluate`) and the offline baselines (:mod:`dtradar_rl.offline.trainer`) read them.
"""

from __future__ import annotations

import json
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import open_atomic, write_atomic

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.task.config import ConfigError, DQNConfig, TwinConfig
from dtradar_rl.envs.memory import batched_env
from dtradar_rl.task.observations import PAPER_COLUMNS, RADIO_FEATURES, Normalizer, build_observations

CHECKPOINT_FORMAT = "dtradar-dqn/1"


class CheckpointError(DtradarError, FileNotFoundError):
    """A checkpoint that is missing or not a dtradar DQN checkpoint."""


class QNetwork(nn.Module):
    """``obs -> [Linear, ReLU] x len(hidden) -> Linear -> 4 action values``."""

    def __init__(self, in_dim: int, hidden: tuple[int, ...], n_actions: int = 4):
        super().__init__()
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(in_dim, h), nn.ReLU()]
            in_dim = h
        layers.append(nn.Linear(in_dim, n_actions))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


# -- files: every write goes to a temporary file first, so a kill leaves the old file or the new one --------------
def save_torch_atomic(obj: Any, path: Path) -> Path:
    """``torch.save`` through :func:`~dtradar_data.core.files.open_atomic` (a hidden ``.NAME.*.tmp`` file in the same
    folder, fsynced, then a rename): a writer killed at any moment leaves the previous file or the new one, whole."""
    path = Path(path)
    with open_atomic(path, "wb") as f:
        torch.save(obj, f)
    return path


def read_checkpoint(path: str | Path, formats: tuple[str, ...], *, what: str, device: str = "cpu") -> dict[str, Any]:
    """The state dict saved at ``path``, or :class:`CheckpointError` naming the file when it is missing, truncated,
    not a torch file or of another format."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {path}" + (" (it is a folder)" if path.is_dir() else ""),
                              hint="train one first, e.g. `make train SCENE=cubicle`, or pass the model.pt it wrote")
    try:
        state = torch.load(path, map_location=device, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError, AttributeError, ImportError) as e:
        raise CheckpointError(f"{path} is damaged or not a torch checkpoint ({type(e).__name__}: {e})",
                              hint="delete it and train again (a run writes model.pt only when it finishes)") from e
    if not isinstance(state, dict) or state.get("format") not in formats:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(f"{path} is not a {what} (format {found!r}, expected {' or '.join(formats)})",
                              hint="pass the model.pt written by `python -m dtradar_rl train` (or `offline`)")
    return state


def write_config(cfg: TwinConfig, directory: Path) -> Path:
    path = Path(directory) / "config.json"
    write_atomic(path, json.dumps(cfg.to_dict(), indent=2) + "\n")
    return path


def save_checkpoint(path: Path, q: QNetwork, cfg: TwinConfig, normalizer: Normalizer, obs_names, ds: Dataset,
                    stats: dict[str, Any] | None = None) -> Path:
    """A self-contained policy: weights, architecture, config, observation preset and normaliser."""
    save_torch_atomic({"format": CHECKPOINT_FORMAT, "config": json.dumps(cfg.to_dict()),
                       "arch": {"in_dim": len(obs_names), "hidden": list(cfg.hidden), "n_actions": 4},
                       "obs": {"preset": cfg.obs, "names": list(obs_names)}, "normalizer": normalizer.to_dict(),
                       "dataset": {"name": ds.name, "version": ds.version}, "stats": stats or {},
                       "q": {k: v.detach().cpu() for k, v in q.state_dict().items()}}, path)
    write_config(cfg, Path(path).parent)
    return Path(path)


@dataclass
class Policy:
    """A trained greedy policy and everything needed to observe a twin the way it was trained."""

    q: QNetwork
    config: TwinConfig
    normalizer: Normalizer
    obs_preset: str
    meta: dict[str, Any]

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions. ``shield=True`` (``neighbors`` preset only) never picks a move into a neighbour that
        the twin shows without radio features (blocked or off the grid), unless every move is such."""
        with torch.no_grad():
            q = self.q(obs)
            if shield:
                flags = obs[..., self.shield_columns()] > 0.5
                q = torch.where(flags | ~flags.any(-1, keepdim=True), q, torch.full_like(q, -torch.inf))
            return q.argmax(-1)

    def shield_columns(self) -> list[int]:
        """Observation columns of the four has-radio flags (``neighbors`` preset), in action order."""
        if self.obs_preset != "neighbors":
            raise ConfigError(f"the obstacle shield needs the 'neighbors' observation preset, "
                              f"this policy observes {self.obs_preset!r}")
        k = len(RADIO_FEATURES) + 1
        return [len(PAPER_COLUMNS) + a * k + k - 1 for a in range(4)]

    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        """A batched env over ``ds`` that observes with this policy's preset and training normaliser."""
        return batched_env(ds, num_envs, memory_radius=getattr(self.config, "memory_radius", 0), obs=self.obs_preset,
                           normalizer=self.normalizer, **kwargs)

    def observations(self, ds: Dataset):
        return build_observations(ds, self.obs_preset, self.normalizer)


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
        raise CheckpointError(f"{path} is a DQN checkpoint with missing or inconsistent parts ({e})",
                              hint="train again; a checkpoint edited by hand cannot be repaired") from e
    q.eval()
    return Policy(q, cfg, normalizer, preset, {"dataset": state.get("dataset"), "stats": state.get("stats", {}),
                                                "path": str(path)})
