"""A trained d3rlpy algorithm as a :class:`~dtradar_rl.agents.policy.Policy`: reloaded from ``model.d3`` and its
``config.json``, and evaluated on the twins like any trained agent.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.ids import MOVING_VARIANT
from dtradar_rl.agents.checkpoints import CheckpointError
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import evaluate_twins
from dtradar_rl.offline.config import OFFLINE_FORMAT, OfflineConfig
from dtradar_rl.offline.formats import import_d3rlpy, quiet_d3rlpy
from dtradar_rl.task.observations import Normalizer


def d3rlpy_device(name: str) -> str:
    """d3rlpy's device string of a torch device name (``cpu`` -> ``cpu:0``)."""
    return name if ":" in name else ("cpu:0" if name == "cpu" else f"{name}:0")


class ActionScores:
    """``obs -> float[N, 4]`` scores of a d3rlpy algorithm's actions (Q-values; BC: policy logits), used by the
    shield to rank the allowed moves."""

    def __init__(self, algo, algorithm: str):
        self.algo, self.algorithm = algo, algorithm

    def __call__(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs.detach().cpu().numpy().astype(np.float32, copy=False)
        if self.algorithm == "bc":  # BC has no values; its categorical policy's logits rank the moves
            impl = self.algo.impl
            with torch.no_grad():
                logits = impl.modules.imitator(torch.as_tensor(x, device=impl.device)).logits
            return logits.cpu().to(obs.device)
        v = [self.algo.predict_value(x, np.full(len(x), a, np.int64)) for a in range(4)]
        return torch.as_tensor(np.stack(v, 1), dtype=torch.float32, device=obs.device)


@dataclass
class OfflinePolicy(Policy):
    """A trained d3rlpy algorithm as a :class:`dtradar_rl.agents.policy.Policy`: greedy moves from ``algo.predict``, the
    same observation preset, normaliser and twin environment, and the same obstacle shield."""

    algo: Any = None
    algorithm: str = ""

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions (``algo.predict``); ``shield=True`` replaces a move into a neighbour sensed as occupied
        with the best allowed move by :class:`ActionScores` (via :meth:`Policy.act`). An agent trained with
        ``--senses memory`` leaves a cell it already stood on ``escape_after`` times by a seeded random move, as the
        online default agent does (:meth:`Policy.act`)."""
        x = obs.detach().reshape(-1, obs.shape[-1]).cpu().numpy()
        a = torch.as_tensor(self.algo.predict(x), dtype=torch.long, device=obs.device).reshape(obs.shape[:-1])
        allowed, stuck = None, self._stuck(obs)
        if shield:
            flags = obs[..., self.shield_columns()] > 0.5
            allowed = flags | ~flags.any(-1, keepdim=True)
            vetoed = ~flags.gather(-1, a[..., None]).squeeze(-1) & flags.any(-1)
            if stuck is not None:  # a robot that escapes moves at random anyway
                vetoed &= ~stuck
            if bool(vetoed.any()):
                a[vetoed] = super().act(obs[vetoed], shield=True)
        if stuck is not None:
            a = torch.where(stuck, self._escape_moves(obs, allowed), a)
        return a


def load_offline_policy(path: str | Path, device: str = "cpu") -> OfflinePolicy:
    """Reload ``model.d3`` (or its directory) with the ``config.json`` written beside it; a run trained on an honest
    log comes back as a :class:`~dtradar_rl.offline.filter_senses.FilteredPolicy`."""
    path = Path(path)
    model = path / "model.d3" if path.is_dir() else path
    meta_path = model.parent / "config.json"
    if not model.exists() or not meta_path.exists():
        raise CheckpointError(
            f"no offline model at {model} (with config.json beside it)",
            hint="train one first, e.g. `make offline SCENE=cubicle`",
        )
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError) as e:
        raise CheckpointError(f"{meta_path} cannot be read ({e})", hint="train again with `make offline`") from e
    if not isinstance(meta, dict) or meta.get("format") != OFFLINE_FORMAT:
        raise CheckpointError(
            f"{meta_path} is not a dtradar offline-RL config",
            hint="pass the model.d3 written by `python -m dtradar_rl offline`",
        )
    d3rlpy = import_d3rlpy()
    with quiet_d3rlpy():
        algo = d3rlpy.load_learnable(str(model), device=d3rlpy_device(device))
    cfg = OfflineConfig.from_dict(meta["config"])
    if cfg.honest:  # it acts through the localisation filter on honest sensing (dtradar_rl.offline.filter_senses)
        from dtradar_rl.offline.filter_senses import FilteredPolicy, map_agent

        info = {"dataset": meta["dataset"], "stats": meta["stats"], "path": str(model), "sensing": cfg.sensing}
        agent = map_agent(cfg.scene, cfg.sensing, cfg.sensing_noise, device)
        return FilteredPolicy(algo, ActionScores(algo, cfg.algorithm), agent, cfg, info)
    return OfflinePolicy(
        q=ActionScores(algo, cfg.algorithm),
        config=cfg,
        normalizer=Normalizer.from_dict(meta["normalizer"]),
        obs_preset=meta["obs"]["preset"],
        meta={"dataset": meta["dataset"], "stats": meta["stats"], "path": str(model)},
        algo=algo,
        algorithm=cfg.algorithm,
    )


def evaluated_variants(cfg: OfflineConfig) -> tuple[str, ...]:
    """``cfg.eval_variants``, the moving twin first when the run learnt on it: an agent is evaluated among the movers
    it was trained with, and on the static twins it may transfer to (empty stays empty: no evaluation)."""
    variants = tuple(cfg.eval_variants)
    if not variants or cfg.variant != MOVING_VARIANT or MOVING_VARIANT in variants:
        return variants
    return (MOVING_VARIANT, *variants)


def evaluate_offline(
    policy: OfflinePolicy, cfg: OfflineConfig, datasets: dict[str, Dataset] | None = None
) -> list[dict[str, Any]]:
    """Rows of :func:`dtradar_rl.evaluation.evaluate.evaluate` on every twin in ``cfg.eval_variants`` (missing ones are
    skipped), unshielded and, with ``cfg.shield`` and the neighbors preset, shielded."""
    rows = evaluate_twins(
        policy,
        cfg.scene,
        evaluated_variants(cfg),
        label=f"{cfg.algorithm}: ",
        pairs=cfg.pairs,
        seed=cfg.eval_seed,
        max_steps=cfg.max_steps or None,
        device=cfg.device,
        shield=cfg.shield,
        datasets=datasets,
        latency=cfg.latency,
        # an honest agent is evaluated under the receiver noise it was logged with (what its filter assumes)
        noise=cfg.sensing_noise if cfg.honest else "none",
    )
    return [{**row, "algorithm": cfg.algorithm} for row, _, _ in rows]


__all__ = [
    "ActionScores",
    "OfflinePolicy",
    "d3rlpy_device",
    "evaluate_offline",
    "evaluated_variants",
    "load_offline_policy",
]
