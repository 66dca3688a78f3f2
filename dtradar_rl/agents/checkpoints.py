"""Checkpoint files: a self-contained ``model.pt`` (weights, architecture, the training config, the observation
preset and the feature normaliser), written atomically, read back with a typed error naming the file.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, InvalidSettingError
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_rl.agents.policy import QNetwork
from dtradar_rl.task.config import TwinConfig
from dtradar_rl.task.observations import Normalizer

CHECKPOINT_FORMAT = "dtradar-dqn/1"
#: ``kind`` of a run's ``last.pt`` (weights plus optimiser, replay and random states, to resume); a ``model.pt`` is
#: ``"model"``. Checkpoints written before ``kind`` was recorded have none (see ``train.saved_runs``).
TRAINING_STATE = "training-state"


class CheckpointError(DtradarError, FileNotFoundError):
    """A checkpoint that is missing or not a dtradar DQN checkpoint."""


class WrongTwinError(InvalidSettingError):
    """A checkpoint trained on another twin (another scene, variant or stored version) than the job works on."""


def twin_record(ds: Dataset) -> dict[str, Any]:
    """What a checkpoint records of the twin it was trained on: ``{"name": "<scene>/<variant>", "version"}``."""
    return {"name": ds.name, "version": ds.version}


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
        raise CheckpointError(
            f"no checkpoint at {path}" + (" (it is a folder)" if path.is_dir() else ""),
            hint="train one first, e.g. `make train SCENE=cubicle`, or pass the model.pt it wrote",
        )
    try:
        state = torch.load(path, map_location=device, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError, AttributeError, ImportError) as e:
        raise CheckpointError(
            f"{path} is damaged or not a torch checkpoint ({type(e).__name__}: {e})",
            hint="delete it and train again (a run writes model.pt only when it finishes)",
        ) from e
    if not isinstance(state, dict) or state.get("format") not in formats:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(
            f"{path} is not a {what} (format {found!r}, expected {' or '.join(formats)})",
            hint="pass the model.pt written by `python -m dtradar_rl train` (or `offline`)",
        )
    return state


def write_config(cfg: TwinConfig, directory: Path) -> Path:
    path = Path(directory) / "config.json"
    write_atomic(path, json.dumps(cfg.to_dict(), indent=2) + "\n")
    return path


def save_checkpoint(
    path: Path,
    q: QNetwork,
    cfg: TwinConfig,
    normalizer: Normalizer,
    obs_names,
    ds: Dataset,
    stats: dict[str, Any] | None = None,
) -> Path:
    """A self-contained policy: weights, architecture, config, observation preset and normaliser."""
    save_torch_atomic(
        {
            "format": CHECKPOINT_FORMAT,
            "kind": "model",
            "config": json.dumps(cfg.to_dict()),
            "arch": {"in_dim": len(obs_names), "hidden": list(cfg.hidden), "n_actions": q.net[-1].out_features},
            "obs": {"preset": cfg.obs, "names": list(obs_names)},
            "normalizer": normalizer.to_dict(),
            "dataset": twin_record(ds),
            "stats": stats or {},
            "q": {k: v.detach().cpu() for k, v in q.state_dict().items()},
        },
        path,
    )
    write_config(cfg, Path(path).parent)
    return Path(path)
