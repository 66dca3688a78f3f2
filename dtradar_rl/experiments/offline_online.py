"""The online agents the offline benchmark compares with (:func:`online_reference`): a privileged online DQN when
one exists or a behaviour acts with one (trained here when needed), or with an honest sensing the default radio-filter
agent. :mod:`dtradar_rl.experiments.offline_bench` runs the benchmark."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from dtradar_rl.evaluation.evaluate import METRICS, evaluate_twins
from dtradar_rl.evaluation.normalized import normalized
from dtradar_rl.experiments.offline_bench_config import EVAL_SEED, NEED_ONLINE, OfflineBenchConfig
from dtradar_rl.task.runs import dqn_checkpoint
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.saved_runs import load_policy


def scores(metrics: dict[str, Any], refs: dict[str, float]) -> dict[str, float]:
    """``metrics`` (success rate, SPL, collisions) with the normalised score of its SPL first."""
    return {"normalized": normalized(metrics["spl"], refs), **{m: float(metrics[m]) for m in METRICS}}


def _scored_twins(policy, cfg: OfflineBenchConfig, twins: dict[str, Any], refs: dict[str, Any], **kwargs):
    """``{variant: scores}`` of ``policy`` on every evaluated twin, greedy and unshielded on the benchmark's pairs
    (``kwargs``: the evaluation's ``noise``, ``latency``)."""
    rows = evaluate_twins(
        policy,
        cfg.scene,
        cfg.variants,
        pairs=cfg.pairs,
        seed=EVAL_SEED,
        device=cfg.device,
        shield=False,
        datasets=twins,
        **kwargs,
    )
    return {r["dataset"].split("/")[1]: scores(r, refs[r["dataset"].split("/")[1]]) for r, _, _ in rows}


def _memoryless(path: Path) -> bool:
    """A checkpoint the epsilon-greedy behaviour can act with (a memory agent's memory is not in a logged step)."""
    return path.is_file() and not getattr(load_policy(path).config, "memory_radius", 0)


def _online_checkpoint(cfg: OfflineBenchConfig, say) -> tuple[Path, dict[str, Any]]:
    path = Path(cfg.checkpoint) if cfg.checkpoint else dqn_checkpoint(cfg.scene)
    if cfg.checkpoint or _memoryless(path):
        return path, {"trained_here": False}
    own = cfg.out_dir / "online_dqn" / "model.pt"  # make train's default agent has a memory: train a tuned one
    if own.is_file():
        return own, {"trained_here": False}
    from dtradar_rl.train.dqn import train

    say(f"no memoryless online DQN at {path}: training one (tuned, {cfg.online_steps} env steps)")
    t0 = time.perf_counter()
    dqn_cfg = replace(
        config_for("tuned", scene=cfg.scene),
        total_env_steps=cfg.online_steps,
        device=cfg.device,
        out=str(cfg.out_dir / "online_dqn"),
        verbose=False,
    )
    result = train(dqn_cfg.validate())
    return result.checkpoint, {"trained_here": True, "train_s": time.perf_counter() - t0, "env_steps": result.env_steps}


def online_reference(
    cfg: OfflineBenchConfig, twins: dict[str, Any], refs: dict[str, Any], say
) -> tuple[Path | None, dict]:
    """The online agent's checkpoint (None when there is none and no behaviour needs one) and its scores; with an
    honest sensing, the scores of the default radio-filter agent beside them (the honest online reference)."""
    if cfg.honest and not any(b in NEED_ONLINE for b in cfg.behaviours):
        return None, _honest_reference(cfg, twins, refs, say)
    if any(b in NEED_ONLINE for b in cfg.behaviours):
        ckpt, info = _online_checkpoint(cfg, say)
    elif cfg.checkpoint or dqn_checkpoint(cfg.scene).is_file():
        ckpt, info = Path(cfg.checkpoint) if cfg.checkpoint else dqn_checkpoint(cfg.scene), {"trained_here": False}
    else:
        return None, {}
    policy = load_policy(ckpt, cfg.device)
    preset = getattr(policy.config, "preset", "") or "?"
    online = {
        "checkpoint": str(ckpt),
        "label": f"online DQN, {preset} preset" + (", trained here" if info.get("trained_here") else ""),
        **info,
        **_scored_twins(policy, cfg, twins, refs),
    }
    say(
        f"online agent {ckpt}: "
        + ", ".join(
            f"{v} score {online[v]['normalized']:.1f} (success {online[v]['success_rate']:.3f})"
            for v in cfg.variants
            if v in online
        )
    )
    return ckpt, online


def _honest_reference(cfg: OfflineBenchConfig, twins: dict[str, Any], refs: dict[str, Any], say) -> dict[str, Any]:
    """The default agent (the radio filter on the blueprint, the benchmark's sensing) scored on every twin, under the
    benchmark's receiver noise: what an honest offline learner is compared with."""
    from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent

    blueprint = twins.get(f"{cfg.scene}/blueprint") or load_dataset(f"{cfg.scene}/blueprint")
    agent = RadioFilterAgent(blueprint, FilterConfig(cfg.scene, cfg.sensing, cfg.sensing_noise), cfg.device)
    online = {
        "checkpoint": "radio-filter (built here; nothing learnt)",
        "label": f"the default radio-filter agent, sensing {cfg.sensing}, noise {cfg.sensing_noise}",
        **_scored_twins(agent, cfg, twins, refs, noise=cfg.sensing_noise, latency=False),
    }
    say(
        "honest reference: "
        + ", ".join(f"{v} score {online[v]['normalized']:.1f}" for v in cfg.variants if v in online)
    )
    return online
