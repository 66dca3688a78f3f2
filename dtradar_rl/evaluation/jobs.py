"""The evaluation jobs: ``make eval`` (a checkpoint on the twins of its scene, beside the classical planner) and
``cross`` (train-on-i x evaluate-on-j over several scenes), each with its config; tables, JSON and path plots.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dtradar_data.core.errors import DatasetNotFoundError, unknown_name
from dtradar_data.core.ids import DATASET_VARIANTS, VARIANTS
from dtradar_rl.agents.checkpoints import TRAINING_STATE
from dtradar_rl.agents.planner import planner_for_scene
from dtradar_rl.agents.radio_filter import RadioFilterAgent, load_agent
from dtradar_rl.evaluation.evaluate import cross_matrix, evaluate_twins, write_results
from dtradar_rl.evaluation.fixed_pair import evaluate_pair
from dtradar_rl.task.config import Config, ConfigError, check_device, check_unique
from dtradar_rl.task.noise import noise_model
from dtradar_rl.task.runs import agent_path, dqn_checkpoint, run_dir
from dtradar_rl.task.sensing import sensing_for
from dtradar_rl.task.twins import check_scenes, load_dataset
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.figures import plot_bars
from dtradar_rl.viz.plots import plot_matrix, plot_moving_paths, plot_paths


@dataclass(frozen=True)
class EvalConfig(Config):
    """Evaluate a trained policy on the twins of its scene (blueprint -> blueprint, blueprint -> dynamic)."""

    scene: str = "cubicle"
    """scene whose twins are evaluated (synthetic = the 42x18 stand-in)"""
    checkpoint: str = ""
    """the agent to evaluate: an agent.json (the default agent, default runs/<scene>/agent/agent.json: make train) or
    a DQN's model.pt"""
    sensing: str = ""
    """evaluate the default agent with another honest sensing (radio, radio-no-proximity, no-angles, no-delay,
    no-gain, no-phase, rssi, no-radio; default: the agent's own)"""
    privileged: bool = True
    """also report the learnt DQN of runs/<scene>/dqn/model.pt when it is trained (make train AGENT=dqn): privileged,
    its observation holds the robot's x, y (an upper bound, labelled so)"""
    variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins to evaluate on (blueprint, dynamic, moving: the moving twin, `make dataset VARIANT=moving`)"""
    pairs: int = 500
    """seeded (start, target) pairs per twin"""
    seed: int = 2024
    """seed of the pairs"""
    max_steps: int = 0
    """episode step limit (0 = 4 * (nx + ny))"""
    shield: bool = True
    """also report the policy with the obstacle shield (moves into neighbours sensed as occupied are masked;
    neighbors preset only)"""
    planner: bool = True
    """also report the classical baseline (fingerprint localisation + breadth-first replanning on the blueprint;
    see dtradar_rl.agents.planner)"""
    noise: str = "realistic"
    """measurement noise the robots' receivers measure with: none, realistic or 2x (see dtradar_rl.task.noise; seeded
    by --seed)"""
    plot_paths: int = 6
    """navigation paths drawn over the coverage map per twin"""
    out: str = ""
    """output directory (default runs/<scene>/eval)"""
    device: str = "cpu"
    """torch device"""

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(1, "pairs")
        self.check_at_least(0, "max_steps", "plot_paths", "seed")

    def validate(self) -> EvalConfig:
        """Every setting, before a policy is loaded or a file written; messages name the --flag."""
        super().validate()
        if not self.variants:
            raise ConfigError("--variants is empty", hint="e.g. --variants blueprint dynamic")
        for v in self.variants:
            if v not in DATASET_VARIANTS:
                raise unknown_name("variant (--variants)", v, DATASET_VARIANTS)
        check_unique(self.variants, "variants")
        check_device(self.device)
        noise_model(self.noise)
        if self.sensing:
            sensing_for(self.sensing)
        return self


@dataclass(frozen=True)
class CrossConfig(Config):
    """Train-on-i x evaluate-on-j matrix over a list of datasets (the cities' cross-quadrant heatmap)."""

    scenes: tuple[str, ...] = ("synthetic",)
    """scenes with a trained policy each (e.g. dallas-q1 dallas-q2 dallas-q3 dallas-q4)"""
    variant: str = "blueprint"
    """twin of each scene to evaluate on"""
    checkpoint_pattern: str = str(dqn_checkpoint("{scene}"))
    """where each scene's policy is ({scene} is replaced)"""
    pairs: int = 300
    """seeded (start, target) pairs per cell of the matrix"""
    seed: int = 2024
    """seed of the pairs"""
    out: str = str(run_dir("cross"))
    """output directory"""

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(1, "pairs")
        self.check_at_least(0, "seed")

    def validate(self) -> CrossConfig:
        super().validate()
        if not self.scenes:
            raise ConfigError("--scenes is empty", hint="name at least one scene with a trained policy")
        check_unique(self.scenes, "scenes")
        if len(self.scenes) > 1 and "{scene}" not in self.checkpoint_pattern:
            raise ConfigError(
                f"--checkpoint-pattern {self.checkpoint_pattern!r} has no {{scene}}: every scene "
                "would get the same policy",
                hint="e.g. runs/{scene}/dqn/model.pt",
            )
        if self.variant not in VARIANTS:
            raise unknown_name("variant (--variant)", self.variant, VARIANTS)
        check_scenes(self.scenes, "scenes", self.variant)  # before any policy is loaded
        return self


def load_agent_or_policy(path: Path, device: str = "cpu", sensing: str = ""):
    """The agent saved at ``path``: a radio-filter agent (``agent.json``; ``sensing`` overrides its own) or a DQN
    policy (``model.pt``). A missing default agent says how to build it."""
    if path.suffix == ".json":
        if not path.exists():
            raise DatasetNotFoundError(
                f"no agent at {path}", hint=f"build the default agent first: make train SCENE={path.parent.parent.name}"
            )
        agent = load_agent(path, device)
        if sensing and sensing != agent.sensing.name:
            agent = RadioFilterAgent.from_agent(agent, sensing)
        return agent
    return load_policy(path, device)


def run_eval(cfg: EvalConfig) -> str:
    ckpt = Path(cfg.checkpoint or agent_path(cfg.scene))
    out = Path(cfg.out or run_dir(cfg.scene, "eval"))
    policy = load_agent_or_policy(ckpt, cfg.device, cfg.sensing)
    for line in describe_checkpoint(policy, ckpt):
        print(line)
    if getattr(policy.config, "fixed_pair", False):
        return _eval_pair(cfg, policy, ckpt, out)
    rows, free = [], {}  # free: each static twin's free cells (a results table names the twin's size)
    learnt = dqn_checkpoint(cfg.scene)
    others = []
    if cfg.privileged and ckpt.suffix == ".json" and learnt.exists():
        others.append(("privileged DQN: ", load_policy(learnt, cfg.device), cfg.shield))
    if cfg.planner:
        others.append(("planner: ", planner_for_scene(cfg.scene, cfg.device), False))
    for row, ds, roll in evaluate_twins(
        policy,
        cfg.scene,
        cfg.variants,
        label="radio filter: " if isinstance(policy, RadioFilterAgent) else "",
        pairs=cfg.pairs,
        seed=cfg.seed,
        max_steps=cfg.max_steps or None,
        device=cfg.device,
        shield=cfg.shield,
        noise=cfg.noise,
    ):
        rows.append(row)
        if not ds.is_moving:
            free[ds.name] = int((~ds.blocked).sum())
        k = min(cfg.plot_paths, len(roll.paths))
        out.mkdir(parents=True, exist_ok=True)
        noisy = "" if cfg.noise == EvalConfig.noise else f"_noise-{cfg.noise}"  # the default level: no suffix
        stem = f"paths_{ds.name.split('/')[1]}{'_shielded' if row['shield'] else ''}{noisy}"
        title = f"{row['case']}: success {row['success_rate']:.2f}, SPL {row['spl']:.2f}"
        if ds.is_moving:  # the episodes in time, robots among the movers: an animation
            plot_moving_paths(
                ds, roll.paths[:1], roll.t0[:1], out / f"{stem}.gif", title=title, successes=list(roll.success[:1])
            )
        else:
            plot_paths(ds, roll.paths[:k], out / f"{stem}.png", successes=list(roll.success[:k]), title=title)
    for label, other, shield in others:
        rows += [
            row
            for row, _, _ in evaluate_twins(
                other,
                cfg.scene,
                cfg.variants,
                label=label,
                pairs=cfg.pairs,
                seed=cfg.seed,
                max_steps=cfg.max_steps or None,
                device=cfg.device,
                shield=shield,
                noise=cfg.noise,
            )
        ]
    config = {
        "eval": dataclasses.asdict(cfg),
        "checkpoint": str(ckpt),
        "train": policy.config.to_dict(),
        "train_stats": policy.meta.get("stats", {}),
        "sensing": {row["case"]: row["sensing"] for row in rows},
        "free_cells": free,
    }
    evaluated = {row["dataset"] for row in rows}
    missing = [f"{cfg.scene}/{v}" for v in cfg.variants if f"{cfg.scene}/{v}" not in evaluated]
    md = write_results(rows, out, config, missing=missing)
    print(md, end="")
    print(f"results: {out / 'results.json'}, {out / 'results.md'}")
    return md


def describe_checkpoint(policy, ckpt: Path) -> list[str]:
    """What ``eval`` says about the checkpoint before its table: a run's training state (``last.pt``) when it is one,
    and the torch threads the run trained with (its reproducibility record, where the checkpoint has one)."""
    stats = policy.meta.get("stats") or {}
    lines = []
    if isinstance(policy, RadioFilterAgent):
        m = policy.meta["dataset"]
        return [
            f"agent: {ckpt} (radio filter on the map {m['name']} version {m['version']}); "
            f"sensing {policy.sensing.name}: {policy.sensing.describe()}"
        ]
    if policy.meta.get("kind") == TRAINING_STATE:
        lines.append(
            f"note: {ckpt} is a run's training state (last.pt, {stats.get('env_steps', '?')} env steps): evaluating "
            f"its weights as they were then; the finished run's weights are in {Path(ckpt).with_name('model.pt')}"
        )
    if stats.get("threads") is not None:
        setting = stats.get("threads_setting")
        lines.append(
            f"trained with {stats['threads']} torch thread(s)"
            + ("" if setting is None else f" (--threads {setting}{' = auto' if setting == 0 else ''})")
        )
    return lines


def _eval_pair(cfg: EvalConfig, policy, ckpt: Path, out: Path) -> str:
    """A fixed-pair agent (the paper's protocol) is evaluated on its own pair on each twin, not on random pairs."""
    rows = []
    for variant in cfg.variants:
        try:
            ds = load_dataset(f"{cfg.scene}/{variant}")
        except DatasetNotFoundError as e:
            print(f"skipping {cfg.scene}/{variant}: {e}")
            continue
        row, pair, roll = evaluate_pair(policy, ds, max_steps=cfg.max_steps or None, device=cfg.device)
        rows.append(row)
        out.mkdir(parents=True, exist_ok=True)
        verdict = f"reached in {int(row['steps'])} steps" if row["success_rate"] else "not reached"
        plot_paths(
            ds,
            roll.paths,
            out / f"paths_{variant}.png",
            successes=list(roll.success),
            title=f"{ds.name}: pair {pair.start} -> {pair.target} {verdict}, shortest {pair.shortest}",
        )
    config = {
        "eval": dataclasses.asdict(cfg),
        "checkpoint": str(ckpt),
        "train": policy.config.to_dict(),
        "train_stats": policy.meta.get("stats", {}),
    }
    md = write_results(rows, out, config)
    print(md, end="")
    print(f"results: {out / 'results.json'}, {out / 'results.md'}")
    return md


def run_cross(cfg: CrossConfig) -> None:
    policies = {s: load_policy(cfg.checkpoint_pattern.format(scene=s)) for s in cfg.scenes}
    datasets = {s: load_dataset(f"{s}/{cfg.variant}") for s in cfg.scenes}
    m = cross_matrix(policies, datasets, pairs=cfg.pairs, seed=cfg.seed)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    for key in ("success", "spl"):
        plot_matrix(np.array(m[key]), m["rows"], m["cols"], out / f"cross_{key}.png", title=f"{key} (train x eval)")
        plot_bars(m[key], m["rows"], m["cols"], out / f"cross_{key}_bars.png", ylabel=key)
    rows = [
        {"case": f"{r} -> {c}", "pairs": cfg.pairs, "success_rate": m["success"][i][j], "spl": m["spl"][i][j]}
        for i, r in enumerate(m["rows"])
        for j, c in enumerate(m["cols"])
    ]
    print(write_results(rows, out, {"cross": dataclasses.asdict(cfg), "matrix": m}, name="cross"), end="")


__all__ = ["CrossConfig", "EvalConfig", "run_cross", "run_eval"]
