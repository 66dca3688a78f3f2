"""What a saved DQN run holds (the checkpoint files themselves are :mod:`dtradar_rl.agents.checkpoints`'s): its
checkpoint loaded back as a greedy :class:`~dtradar_rl.agents.policy.Policy` with its
:class:`~dtradar_rl.train.config.DQNConfig`; which twin a checkpoint was trained on; and which run a run folder holds.

A run folder (``--out``) belongs to one scene and one config family: :func:`check_run_folder` refuses, before any
file is touched, a run that would continue (``--resume``) or overwrite another scene's run, or resume a run of
another config family whose weights and saved episodes would not fit.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import InvalidSettingError
from dtradar_rl.agents.checkpoints import (
    CHECKPOINT_FORMAT,
    TRAINING_STATE,
    CheckpointError,
    WrongTwinError,
    read_checkpoint,
)
from dtradar_rl.agents.policy import Policy, QNetwork
from dtradar_rl.task.config import flag
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.train.config import DQNConfig


class RunFolderError(InvalidSettingError):
    """An ``--out`` folder that holds another scene's run, or a run that ``--resume`` cannot continue."""


#: Settings a resumed run must share with the run in its folder: its network's input and layers, the robots and
#: episode state saved with it (augmentation masks, noise errors, memories), and what its reward and pairs mean.
RESUME_FAMILY: tuple[str, ...] = (
    "preset",
    "obs",
    "sense_radius",
    "clock",
    "wait_action",
    "reward",
    "mover_penalty",
    "hidden",
    "num_envs",
    "memory_radius",
    "memory_bumps",
    "memory_visits",
    "aug_obstacles",
    "noise",
    "pair",
    "start",
    "target",
)


def load_policy(path: str | Path, device: str = "cpu") -> Policy:
    """The greedy DQN policy saved at ``path``: a ``model.pt``, or the ``last.pt`` a run writes while it trains (its
    training state: the same weights, config and normaliser; ``meta["kind"]`` says which)."""
    state = read_checkpoint(path, (CHECKPOINT_FORMAT,), what="dtradar DQN checkpoint (model.pt)", device=device)
    training_state = is_training_state(state)
    try:
        cfg = DQNConfig.from_dict(json.loads(state["config"]))
        if training_state:  # last.pt: no architecture record; the weights and the config give it
            arch = {"in_dim": int(state["q"]["net.0.weight"].shape[1]), "hidden": list(cfg.hidden)}
            arch["n_actions"] = int(state["q"][f"net.{2 * len(cfg.hidden)}.weight"].shape[0])
            preset = cfg.obs
        else:
            arch, preset = state["arch"], state["obs"]["preset"]
        _check_actions(path, arch, cfg)
        q = QNetwork(arch["in_dim"], tuple(arch["hidden"]), arch["n_actions"]).to(device)
        q.load_state_dict(state["q"])
        normalizer = Normalizer.from_dict(state["normalizer"])
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as e:
        if training_state:
            raise CheckpointError(
                f"{path} is a training-state checkpoint (last.pt) with missing or inconsistent parts ({e})",
                hint=f"evaluate the model.pt beside it ({Path(path).with_name('model.pt')}), or resume the run "
                "with --resume to write one",
            ) from e
        raise CheckpointError(
            f"{path} is a DQN checkpoint with missing or inconsistent parts ({e})",
            hint="train again; a checkpoint edited by hand cannot be repaired",
        ) from e
    q.eval()
    if training_state:
        stats = {
            "env_steps": state.get("env_steps"),
            "updates": state.get("updates"),
            "episodes": len(state.get("episodes", ())),
            **(state.get("stats") or {}),
        }
    else:
        stats = state.get("stats", {})
    return Policy(
        q,
        cfg,
        normalizer,
        preset,
        {
            # checkpoints without the twin's record (written before it): the config's scene and variant
            "dataset": state.get("dataset") or {"name": f"{cfg.scene}/{cfg.variant}", "version": None},
            "stats": stats,
            "path": str(path),
            "kind": TRAINING_STATE if training_state else "model",
        },
    )


def _check_actions(path: str | Path, arch: dict[str, Any], cfg: DQNConfig) -> None:
    """:class:`CheckpointError` when the saved network's action count is not its config's (4 moves, 5 with
    ``wait_action``): acting with it would give the env actions it does not have, or drop one it was trained on."""
    want = 4 + int(cfg.wait_action)
    if int(arch["n_actions"]) != want:
        raise CheckpointError(
            f"{path}: the network has {arch['n_actions']} actions, its config ({flag('wait_action')}="
            f"{cfg.wait_action}) {want}",
            hint="train again; a checkpoint edited by hand cannot be repaired",
        )


def is_training_state(state: dict[str, Any]) -> bool:
    """Whether a checkpoint's state is a run's training state (``last.pt``: optimiser, replay, random states), not a
    finished ``model.pt``; checkpoints written before ``kind`` was recorded are told by their optimiser."""
    return state.get("kind") == TRAINING_STATE or ("arch" not in state and "optimizer" in state)


# -- which twin ------------------------------------------------------------------------------------------------------
def trained_twin(policy: Policy) -> dict[str, Any]:
    """``{"scene", "variant", "version"}`` of the twin ``policy`` was trained on: the checkpoint's dataset record (every
    ``model.pt`` has one), else its config's scene and variant (version None)."""
    ds = policy.meta.get("dataset") or {}
    scene, _, variant = str(ds.get("name") or "").partition("/")
    return {
        "scene": scene or policy.config.scene,
        "variant": variant or policy.config.variant,
        "version": ds.get("version"),
    }


def check_trained_on_scene(policy: Policy, scene: str, *, option: str = "checkpoint") -> dict[str, Any]:
    """:class:`WrongTwinError` unless ``policy`` was trained on a twin of ``scene`` (the blueprint agent that ``make
    adapt`` fine-tunes on the scene's changed twin, say); returns the twin it was trained on."""
    twin = trained_twin(policy)
    if twin["scene"] != scene:
        path = policy.meta.get("path", "the checkpoint")
        raise WrongTwinError(
            f"{flag(option)} {path} was trained on {twin['scene']}/{twin['variant']}, not on a twin of {scene}: its "
            "network knows the other scene's cells and radio features",
            hint=f"pass a checkpoint trained on {scene} (make train SCENE={scene}: runs/{scene}/dqn/model.pt), "
            f"or --scene {twin['scene']}",
        )
    return twin


def check_same_twin(policy: Policy, ds: Dataset, *, what: str = "the checkpoint") -> None:
    """:class:`WrongTwinError` unless ``policy`` was trained on ``ds`` itself: the same ``scene/variant`` and, where
    both record one, the same stored version (a rebuilt twin has other features)."""
    twin = trained_twin(policy)
    name = f"{twin['scene']}/{twin['variant']}"
    if name != ds.name:
        raise WrongTwinError(
            f"{what} was trained on {name}, not on {ds.name}",
            hint=f"use a checkpoint trained on {ds.name}, or work on {name}",
        )
    if twin["version"] and ds.version and twin["version"] != ds.version:
        raise WrongTwinError(
            f"{what} was trained on version {twin['version']} of {name}; the store's is {ds.version}",
            hint="train again on this version, or load the checkpoint's version with --revision",
        )


# -- which run a folder holds --------------------------------------------------------------------------------------
def folder_owner(out: Path) -> dict[str, Any] | None:
    """The config of the run in ``out`` (its ``config.json``) when it holds a run's weights (``model.pt`` or
    ``last.pt``), else None."""
    out = Path(out)
    if not ((out / "model.pt").is_file() or (out / "last.pt").is_file()):
        return None
    try:
        owner = json.loads((out / "config.json").read_text())
    except (OSError, ValueError):
        return None
    return owner if isinstance(owner, dict) else None


def check_run_folder(cfg: DQNConfig, out: Path) -> dict[str, Any] | None:
    """Refuse (:class:`RunFolderError`, nothing written yet) a run whose ``out`` folder holds another scene's run, and a
    ``--resume`` of a run of another config family; returns the state to resume from (``out/last.pt``) or None."""
    out = Path(out)
    owner = folder_owner(out)
    if owner is not None:
        _check_scene(cfg, out, owner)
    if not (cfg.resume and (out / "last.pt").exists()):
        return None
    state = read_checkpoint(
        out / "last.pt", (CHECKPOINT_FORMAT,), what="resumable DQN run (last.pt)", device=cfg.device
    )
    if not is_training_state(state) or "optimizer" not in state:
        raise RunFolderError(
            f"{out / 'last.pt'} holds no training state to resume (no optimiser, replay or random states)",
            hint=f"pick another --out, or train again without --resume (it replaces the run in {out})",
        )
    try:
        saved = json.loads(state["config"])
    except (KeyError, TypeError, ValueError) as e:
        raise CheckpointError(
            f"{out / 'last.pt'} has no readable config ({e})", hint="train again without --resume"
        ) from e
    _check_scene(cfg, out, saved)
    mine = cfg.to_dict()
    differs = [k for k in RESUME_FAMILY if k in saved and _norm(saved[k]) != _norm(mine.get(k))]
    if differs:
        listing = ", ".join(f"{flag(k)} {_show(saved[k])} (now {_show(mine.get(k))})" for k in differs)
        raise RunFolderError(
            f"--resume: {out} holds a run of another config family: {listing}; its weights and saved episodes "
            "do not fit this run",
            hint=f"pick another --out for this run, or resume with the run's settings ({_args(saved, differs)})",
        )
    return state


def check_resumed_twin(state: dict[str, Any], ds: Dataset, out: Path) -> None:
    """The twin a resumed run loaded is the one its ``last.pt`` was trained on (where the state records it)."""
    recorded = state.get("dataset") or {}
    if recorded.get("version") and ds.version and recorded["version"] != ds.version:
        raise RunFolderError(
            f"--resume: {out / 'last.pt'} was trained on version {recorded['version']} of {recorded.get('name')}; "
            f"the store's is now {ds.version}: its replay buffer holds the old twin's features",
            hint="pick another --out and train on this version, or resume with --revision " + recorded["version"],
        )


def _check_scene(cfg: DQNConfig, out: Path, owner: dict[str, Any]) -> None:
    theirs = f"{owner.get('scene')}/{owner.get('variant', 'blueprint')}"
    mine = f"{cfg.scene}/{cfg.variant}"
    if theirs != mine:
        doing = "resuming would continue its weights" if cfg.resume else "training would overwrite it"
        raise RunFolderError(
            f"--out {out} holds a run of {theirs}, and this run trains {mine}: {doing} and rewrite the folder "
            f"under {mine}'s name",
            hint=f"pick another --out for {mine} (the default is runs/{cfg.scene}/dqn), or delete {out} first",
        )


def _norm(v: Any) -> Any:
    return list(v) if isinstance(v, (list, tuple)) else v


def _show(v: Any) -> str:
    return " ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v)


def _args(saved: dict[str, Any], names: list[str]) -> str:
    parts = []
    for k in names:
        v = saved[k]
        if isinstance(v, bool):
            parts.append(flag(k) if v else f"--no-{flag(k)[2:]}")
        elif v is not None:
            parts.append(f"{flag(k)} {_show(v)}")
    return " ".join(parts)


__all__ = [
    "RESUME_FAMILY",
    "RunFolderError",
    "check_resumed_twin",
    "check_run_folder",
    "check_same_twin",
    "check_trained_on_scene",
    "folder_owner",
    "is_training_state",
    "load_policy",
    "trained_twin",
]
