"""Twin update: when a twin changes, fine-tune the blueprint agent on the new table, and show the time it takes.

    python -m dtradar_rl adapt --scene cubicle      # runs/<scene>/dqn/model.pt fine-tuned on cubicle/dynamic

The blueprint checkpoint's network and normaliser are the starting point; DQN (:func:`dtradar_rl.train.dqn.train`) then
trains on the changed twin with its own breadth-first shaping, little exploration, a small constant learning rate
and the checkpoint's obstacle augmentation. The changed map is known (it was just built, and the shaping already
reads it), so by default the update is also told the right move: a large-margin loss (DQfD, Hester et al. 2018)
pulls the value of the twin's breadth-first shortest moves above the others in every state the agent visits
(``--expert-weight``, 0 = plain DQN). The policy still acts from its observation alone.

Every ``eval_every_s`` seconds of training the greedy policy is evaluated on seeded pairs of the changed twin,
giving success and SPL against seconds of training (seconds in the training loop: neither the evaluations nor the
set-up of loading the twin and building its tables, about a second, count). The same seconds then fine-tune with
plain DQN (``finetune-dqn``, with ``plain``) and train the checkpoint's preset from scratch with the same loss
(``scratch``), for comparison. Writes ``adapt.{json,md}``, ``curve.csv`` and ``curve.png`` to
``runs/<scene>/adapt``.

The changed twin must be traced as the checkpoint's blueprint was (the ray-tracing settings each dataset records in
``meta["rt"]``; :func:`check_traced_alike`). A twin of another radio (carrier frequency, receiving antenna: what a
feature value means) is refused: the checkpoint's network and normaliser learned the blueprint's radio, so the run
would not be an update of the same agent. Any other difference (depth, interaction types, samples, engine) is
warned about and recorded in ``adapt.json``: a cheaper or finer changed twin can be intended, but the curves then
measure that change of settings together with the change of the scene.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_data.rt.settings import flag as rt_flag
from dtradar_data.store import read_meta, resolve
from dtradar_rl.agents.checkpoints import WrongTwinError
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.config import ConfigError, JobConfig, flag
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.runs import dqn_checkpoint, run_dir
from dtradar_rl.task.twins import is_synthetic, load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import check_trained_on_scene, load_policy, trained_twin
from dtradar_rl.viz.plots import plot_adapt_curves


@dataclass(frozen=True)
class AdaptConfig(JobConfig):
    """Fine-tune a blueprint agent on a changed twin; success against seconds, beside training from scratch
    (``--out`` default: runs/<scene>/adapt)."""

    variant: str = "dynamic"
    """the changed twin"""
    checkpoint: str = ""
    """blueprint agent to start from (default runs/<scene>/dqn/model.pt)"""
    seconds: float = 20.0
    """training seconds for the fine-tuning and for the from-scratch comparison (evaluation not counted)"""
    eval_every_s: float = 2.0
    """evaluate the greedy policy every this many seconds of training"""
    pairs: int = 500
    """seeded (start, target) pairs of each evaluation"""
    pair_seed: int = 2024
    """seed of the pairs (the same as make eval)"""
    eps: float = 0.05
    """exploration rate while fine-tuning (the start is already a good policy)"""
    lr: float = 3e-5
    """Adam learning rate while fine-tuning (constant; Adam's first steps move every weight by about this much,
    and at 1e-4 they cost the blueprint agent 2-4 points before it gains anything)"""
    learning_starts: int = 4_096
    """environment steps collected before the first fine-tuning update"""
    aug_obstacles: int = -1
    """extra random obstacles per episode while fine-tuning (-1 = as the checkpoint was trained: a fine-tuned memory
    agent keeps meeting dead ends, so it does not unlearn them on the few new ones)"""
    env_steps_per_update: int = 16
    """environment steps per gradient update while fine-tuning (updates, not steps, cost the time)"""
    expert_weight: float = 1.0
    """weight of the large-margin loss towards the changed twin's breadth-first shortest moves (DQfD; 0 = plain DQN
    fine-tuning). The changed map is known (it was just built, and its shaping already uses it), so the update can
    be told the right move in every state the agent visits; the scratch run gets the same loss"""
    expert_margin: float = 1.0
    """margin of that loss"""
    plain: bool = True
    """also fine-tune with plain DQN (no expert loss) for the same seconds, to show what the expert loss buys"""
    scratch: bool = True
    """also train the checkpoint's preset from scratch on the changed twin for the same seconds"""

    def check_ranges(self) -> None:
        super().check_ranges()
        for name in ("seconds", "eval_every_s", "lr", "expert_margin"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{flag(name)} must be > 0, got {getattr(self, name)}")
        self.check_at_least(1, "pairs", "env_steps_per_update")
        self.check_at_least(0, "learning_starts", "pair_seed", "expert_weight")
        self.check_at_least(-1, "aug_obstacles")
        self.check_within(0, 1, "eps")


#: Ray-tracing settings that say what a feature value means, the radio observed: a changed twin traced with others is
#: refused (the module docstring). Every other recorded setting is warned about.
RADIO_SETTINGS: tuple[str, ...] = ("frequency_hz", "rx_pattern", "rx_polarization")
#: What ``meta["rt"]`` records beside the settings (the reduction's text, the solver's name, the Mitsuba variant).
NOT_SETTINGS: tuple[str, ...] = ("reduction", "solver", "mitsuba_variant")


def _show(value: Any) -> str:
    if value is None:
        return "(not recorded)"
    return f"{value:g}" if isinstance(value, float) else str(value)


def check_traced_alike(start: Policy, ds: Dataset, ckpt: Path) -> dict[str, list[Any]]:
    """``{setting: [blueprint's, changed twin's]}`` of the ray-tracing settings in which ``ds`` differs from the twin
    ``start`` was trained on (that stored version's ``meta.json``); :class:`WrongTwinError` for one of
    :data:`RADIO_SETTINGS`, a warning for the others. Empty, with nothing checked, when either twin records no
    settings (a synthetic one) or the checkpoint's version is not in the store."""
    twin = trained_twin(start)
    name = f"{twin['scene']}/{twin['variant']}"
    mine = ds.meta.get("rt")
    if not isinstance(mine, dict) or is_synthetic(twin["scene"]) or not twin["version"]:
        return {}
    try:
        theirs = read_meta(resolve(name, twin["version"])[2]).get("rt")
    except DtradarError:  # a pulled checkpoint whose twin is not stored here: nothing to compare with
        return {}
    if not isinstance(theirs, dict):
        return {}
    keys = sorted((set(mine) | set(theirs)) - set(NOT_SETTINGS))
    differs = {k: [theirs.get(k), mine.get(k)] for k in keys if theirs.get(k) != mine.get(k)}
    listing = "; ".join(f"{rt_flag(k)} {_show(a)} there, {_show(b)} here" for k, (a, b) in differs.items())
    radio = [k for k in differs if k in RADIO_SETTINGS]
    if radio:
        rebuild = " ".join(f"{rt_flag(k)} {_show(differs[k][0])}" for k in radio)
        raise WrongTwinError(
            f"{ckpt} was trained on {name}@{twin['version']}, traced with other radio settings than {ds.name}@"
            f"{ds.version} ({listing}): its network and normaliser learned another radio, so fine-tuning it there is "
            "no update of the same agent",
            hint=f"rebuild {ds.name} as the blueprint was traced (`python -m dtradar_data build --scene "
            f"{twin['scene']} --variant {ds.name.split('/')[1]} {rebuild}`), or start from an agent trained on a "
            f"blueprint traced like {ds.name}",
        )
    if differs:
        warnings.warn(
            f"{ckpt} was trained on {name}@{twin['version']}, traced with other ray-tracing settings than "
            f"{ds.name}@{ds.version} ({listing}): the curves measure that change together with the change of the "
            "scene (recorded in adapt.json as rt_differences)",
            UserWarning,
            stacklevel=3,
        )
    return differs


@dataclass
class AdaptResult:
    out_dir: Path
    #: per run ("finetune", "scratch"): rows ``{"train_s", "env_steps", "success_rate", "spl", "collisions"}``
    curves: dict[str, list[dict[str, float]]]
    markdown: str


def _curve(cfg: AdaptConfig, label: str, train_cfg, ds, init: Policy | None, out: Path) -> list[dict[str, float]]:
    """Train ``train_cfg`` on ``ds`` (from ``init``'s weights if given) for ``cfg.seconds``, evaluating as it goes."""
    rows: list[dict[str, float]] = []
    holder: dict[str, Any] = {}

    def record(q, env_steps: int, train_s: float) -> None:
        policy = Policy(q, train_cfg, holder["normalizer"], train_cfg.obs, {"dataset": {"name": ds.name}})
        was_training = q.training
        q.eval()
        m, _ = evaluate(policy, ds, pairs=cfg.pairs, seed=cfg.pair_seed, latency=False)
        q.train(was_training)
        rows.append(
            {
                "train_s": round(train_s, 3),
                "env_steps": env_steps,
                "success_rate": m.success_rate,
                "spl": m.spl,
                "collisions": m.collisions,
            }
        )
        if cfg.verbose:
            print(f"{label:>9s} {train_s:6.1f} s  {env_steps:>8d} steps  success {m.success_rate:.3f}  SPL {m.spl:.3f}")

    def callback(q, env_steps: int, train_s: float) -> bool:
        if train_s >= holder["next"] or train_s >= cfg.seconds:
            record(q, env_steps, train_s)
            holder["next"] = (train_s // cfg.eval_every_s + 1) * cfg.eval_every_s
        return train_s >= cfg.seconds

    holder["next"] = cfg.eval_every_s
    if init is not None:
        holder["normalizer"] = init.normalizer
        record(init.q, 0, 0.0)  # zero-shot: the blueprint agent before any update
        train(train_cfg, ds, init=init.q.state_dict(), normalizer=init.normalizer, callback=callback)
    else:
        holder["normalizer"] = Normalizer.fit(ds)
        train(train_cfg, ds, callback=callback)
    write_atomic(out / label / "curve.json", json.dumps(rows, indent=2) + "\n")
    return rows


def adapt(cfg: AdaptConfig) -> AdaptResult:
    """Fine-tune (and, with ``scratch``, train from scratch) on ``<scene>/<variant>``; write the curves."""
    cfg = cfg.validate()
    ckpt = Path(cfg.checkpoint or dqn_checkpoint(cfg.scene))
    out = Path(cfg.out or run_dir(cfg.scene, "adapt"))
    start = load_policy(ckpt)
    twin = check_trained_on_scene(start, cfg.scene)  # another scene's agent knows other cells: refused, as make log
    if twin["variant"] == cfg.variant and cfg.verbose:
        print(f"note: {ckpt} was trained on {cfg.scene}/{cfg.variant} itself; fine-tuning it there changes little")
    ds = load_dataset(f"{cfg.scene}/{cfg.variant}")
    rt_differences = check_traced_alike(start, ds, ckpt)  # another radio refused, other settings warned about
    base = start.config
    if cfg.expert_weight > 0 and base.reward != "geodesic":
        raise ConfigError(
            f"{ckpt} was trained with --reward {base.reward}; the expert loss reads the breadth-first "
            f"distance tables of the geodesic reward",
            hint="fine-tune with --expert-weight 0",
        )
    # the clock, not the step budget, ends both runs: exploration and learning rate stay at the fine-tuning values
    common = {
        "scene": cfg.scene,
        "variant": cfg.variant,
        "seed": cfg.seed,
        "threads": cfg.threads,
        "verbose": False,
        "checkpoint_every": 0,
        "save_replay": False,
        "total_env_steps": 50_000_000,
    }
    finetune_cfg = dataclasses.replace(
        base,
        **common,
        aug_obstacles=cfg.aug_obstacles if cfg.aug_obstacles >= 0 else base.aug_obstacles,
        eps_start=cfg.eps,
        eps_end=cfg.eps,
        lr=cfg.lr,
        lr_end=-1.0,
        learning_starts=cfg.learning_starts,
        env_steps_per_update=cfg.env_steps_per_update,
        expert_weight=cfg.expert_weight,
        expert_margin=cfg.expert_margin,
        out=str(out / "finetune"),
        resume=False,
    ).validate()
    curves = {"finetune": _curve(cfg, "finetune", finetune_cfg, ds, start, out)}
    if cfg.plain and cfg.expert_weight > 0:
        plain_cfg = dataclasses.replace(finetune_cfg, expert_weight=0.0, out=str(out / "finetune-dqn")).validate()
        curves["finetune-dqn"] = _curve(cfg, "finetune-dqn", plain_cfg, ds, start, out)
    if cfg.scratch:
        # from scratch: the preset, with its exploration decay fitted to the steps the seconds allow (a constant
        # learning rate, since the clock ends the run)
        steps_per_s = curves["finetune"][-1]["env_steps"] / max(curves["finetune"][-1]["train_s"], 1e-9)
        expected = steps_per_s * cfg.seconds
        preset = config_for(getattr(base, "preset", "tuned"))
        scratch_cfg = config_for(
            preset.preset,
            **{
                **common,
                "aug_obstacles": 0,
                "out": str(out / "scratch"),
                "eps_decay_fraction": min(1.0, preset.eps_decay_fraction * expected / common["total_env_steps"]),
                "lr_end": -1.0,
                "learning_starts": min(preset.learning_starts, int(expected / 4)),
                "expert_weight": cfg.expert_weight,
                "expert_margin": cfg.expert_margin,
            },
        )
        curves["scratch"] = _curve(cfg, "scratch", scratch_cfg, ds, None, out)
    md = _report(cfg, ckpt, curves, out, rt_differences)
    return AdaptResult(out, curves, md)


def first_time_at(rows: list[dict[str, float]], success: float) -> float | None:
    """Training seconds of the first evaluation with at least ``success``, or None."""
    return next((r["train_s"] for r in rows if r["success_rate"] >= success), None)


def _report(
    cfg: AdaptConfig,
    ckpt: Path,
    curves: dict[str, list[dict[str, float]]],
    out: Path,
    rt_differences: dict[str, list[Any]],
) -> str:
    out.mkdir(parents=True, exist_ok=True)
    with open_atomic(out / "curve.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "train_s", "env_steps", "success_rate", "spl", "collisions"])
        for run, rows in curves.items():
            w.writerows([run, r["train_s"], r["env_steps"], r["success_rate"], r["spl"], r["collisions"]] for r in rows)
    plot_adapt_curves(curves, out / "curve.png", title=f"{cfg.scene}/{cfg.variant}: success vs training seconds")
    lines = ["| run | start | end: success / SPL | seconds to >= 0.95 | seconds to >= 0.99 |", "|---|---|---|---|---|"]
    for run, rows in curves.items():
        t95, t99 = first_time_at(rows, 0.95), first_time_at(rows, 0.99)
        lines.append(
            f"| {run} | {rows[0]['success_rate']:.3f} | {rows[-1]['success_rate']:.3f} / "
            f"{rows[-1]['spl']:.3f} | {'-' if t95 is None else f'{t95:.1f}'} | "
            f"{'-' if t99 is None else f'{t99:.1f}'} |"
        )
    md = "\n".join(lines) + "\n"
    write_atomic(out / "adapt.md", md)
    write_atomic(
        out / "adapt.json",
        json.dumps(
            {
                "config": dataclasses.asdict(cfg),
                "checkpoint": str(ckpt),
                "rt_differences": rt_differences,
                "curves": curves,
            },
            indent=2,
        )
        + "\n",
    )
    return md
