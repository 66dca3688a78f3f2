"""The medium agent of the ``medium``, ``medium-replay`` and ``mixed`` families: an online DQN trained once per recipe
until its normalised score reaches the recipe's target, and cached under
``<root>/logged/<scene>/<variant>/medium/agents/<key>/`` (``model.pt``, ``last.pt`` with its replay buffer,
``medium.json``), where ``key`` hashes the twin, the recipe, the seed, the logging settings and the library versions.
Two processes training the same agent take turns; the second reuses the first's.

A cached agent is served only when its content is the one its record describes (:func:`cached_agent_problem`): the
record's inputs hash to the folder's key, and ``model.pt`` (what ``medium`` and ``mixed`` act with) and ``last.pt``
(the replay buffer ``medium-replay`` logs) have the sha256 the record took when the run was installed. A folder name
says only which inputs it was trained for: a file damaged on disk or put back from another run would otherwise serve
a wrong agent or another run's buffer. Any mismatch trains the agent again, saying why."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core import layout as P
from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import sha256_file, waiting_lock, write_atomic
from dtradar_data.store import held_stage, library_versions, version_id
from dtradar_data.store.logged import LOGGED_LIBRARIES, logged_dir, parse_logged_id
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.evaluation.normalized import normalized, reference_scores
from dtradar_rl.offline.behaviours import MEDIUM_TOLERANCE, BehaviourConfig, BehaviourPolicy, BehaviourSpec
from dtradar_rl.offline.log_settings import parent_version, settings_of
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer

#: The medium agents' folder inside ``<root>/logged/<scene>/<variant>/medium`` (not a version: no hash name).
MEDIUM_AGENTS = "agents"
MEDIUM_RECORD = "medium.json"
_AGENT_STAGE = "logged-agent-"


@dataclass(frozen=True)
class MediumAgent:
    """A trained medium agent in its cache folder: ``model.pt`` (the agent at the stop), ``last.pt`` (its training
    state, with the replay buffer of everything it collected) and ``medium.json`` (:attr:`record`)."""

    path: Path
    record: dict[str, Any]

    @property
    def checkpoint(self) -> Path:
        return self.path / "model.pt"

    @property
    def last(self) -> Path:
        return self.path / "last.pt"

    def summary(self) -> dict[str, Any]:
        """What a logged dataset's meta records of it (no history)."""
        keys = ("key", "stopped_at_env_steps", "updates", "episodes", "train_s", "spl", "score", "target")
        keys += ("tolerance", "within_tolerance", "checkpoint_sha256", "evaluations")
        return {k: self.record.get(k) for k in keys}


def medium_key_inputs(cfg: BehaviourConfig, ds: Dataset) -> dict[str, Any]:
    """What identifies a medium agent: the twin (name and content), the recipe, the seed, the logging settings (robots,
    observation preset, reward, step limit, device kind) and the library versions."""
    return {
        "parent": ds.name,
        "parent_version": parent_version(ds),
        "medium": cfg.spec().medium_recipe(),
        "seed": int(cfg.seed),
        # the agent acts on the privileged preset whatever the log records: one agent for every --sensing
        "settings": settings_of(dataclasses.replace(cfg, sensing="privileged"), ds),
        "library_versions": library_versions(LOGGED_LIBRARIES),
    }


def medium_agent_dir(cfg: BehaviourConfig, key: str) -> Path:
    return logged_dir(parse_logged_id(f"{cfg.scene}/{cfg.variant}/medium")) / MEDIUM_AGENTS / key


def cached_agent_problem(path: Path, key: str) -> str | None:
    """Why the cache folder ``path`` of the agent ``key`` cannot be served (None when it can: module docstring)."""
    try:
        record = json.loads((path / MEDIUM_RECORD).read_text())
    except (OSError, ValueError) as exc:
        return f"its {MEDIUM_RECORD} cannot be read ({type(exc).__name__})"
    if not isinstance(record, dict) or record.get("key") != key or version_id(record.get("inputs") or {}) != key:
        return f"its {MEDIUM_RECORD} is not the record of agent {key} (its inputs hash to another key)"
    agent = MediumAgent(path, record)
    for file, field in ((agent.checkpoint, "checkpoint_sha256"), (agent.last, "last_sha256")):
        if not record.get(field):
            return f"its record has no sha256 of {file.name} (written before the cache was checked)"
        try:
            if sha256_file(file) != record[field]:
                return f"its {file.name} is not the one trained (sha256 differs from its record)"
        except OSError:
            return f"its {file.name} is missing"
    return None


def _stored_agent(path: Path, key: str, say=print) -> MediumAgent | None:
    """The cached agent in ``path`` when its content checks out; None (said, when there was one) otherwise."""
    if not path.exists():
        return None
    why = cached_agent_problem(path, key)
    if why is None:
        return MediumAgent(path, json.loads((path / MEDIUM_RECORD).read_text()))
    say(f"medium agent {key}: the cached copy in {path} cannot be used ({why}): training it again")
    return None


def medium_agent(cfg: BehaviourConfig, ds: Dataset, say=print) -> MediumAgent:
    """The medium agent of ``cfg`` on ``ds``: the cached one when its folder is whole, else trained now (and a
    damaged folder replaced). Two processes take turns; the second reuses the first's agent."""
    inputs = medium_key_inputs(cfg, ds)
    key = version_id(inputs)
    path = medium_agent_dir(cfg, key)
    with waiting_lock(
        path.parent / f".{key}.lock", f"training the medium agent {key} of {ds.name}", then="this process reuses it"
    ):
        agent = _stored_agent(path, key, say)
        if agent is not None:
            say(
                f"medium agent {key}: reused ({agent.record['stopped_at_env_steps']} env steps, normalised score "
                f"{agent.record['score']:.1f})"
            )
            return agent
        return _train_medium(cfg, ds, inputs, key, path, say)


def _train_medium(cfg: BehaviourConfig, ds: Dataset, inputs: dict[str, Any], key: str, dest: Path, say) -> MediumAgent:
    """Train the online DQN of the recipe, evaluating the epsilon-greedy agent every ``eval_every`` environment steps
    on the normalised score's pairs, and stop at the first evaluation at or above the target."""
    import torch

    from dtradar_rl.train.dqn import train

    recipe = inputs["medium"]
    refs = reference_scores(ds, pairs=recipe["pairs"], seed=recipe["eval_seed"], device=cfg.device)
    normalizer = Normalizer.fit(ds)
    pairs = sample_eval_pairs(ds, recipe["pairs"], recipe["eval_seed"])
    history: list[list[float]] = []
    say(
        f"training the medium agent {key} on {ds.name} ({recipe['preset']} DQN, seed {cfg.seed}, up to "
        f"{recipe['budget']} env steps, until its normalised score reaches {recipe['target']:g})"
    )
    threads = torch.get_num_threads()
    with held_stage(P.work_root(), _AGENT_STAGE) as stage:
        out = stage / "run"
        dqn_cfg = _dqn_config(cfg, recipe, inputs["settings"], out)
        callback = _evaluate_until_target(cfg, ds, recipe, dqn_cfg, normalizer, refs, pairs, history, say)
        try:
            result = train(dqn_cfg, ds, normalizer=normalizer, callback=callback)
        finally:
            torch.set_num_threads(threads)
        _check_reached(ds, recipe, history, result)
        record = _medium_record(key, inputs, result, refs, history, out / "model.pt")
        _install(record, out, dest, stage)
    _say_stopped(key, record, say)
    return MediumAgent(dest, record)


def _dqn_config(cfg: BehaviourConfig, recipe: dict[str, Any], settings: dict[str, Any], out: Path):
    """The DQN run of the recipe on the logging settings, written to ``out``, with a replay buffer large enough
    never to wrap: the medium-replay family logs every transition it collected."""
    from dtradar_rl.train.config import config_for

    return config_for(
        recipe["preset"],
        scene=cfg.scene,
        variant=cfg.variant,
        revision=cfg.revision,
        obs=cfg.obs,
        reward=cfg.reward,
        max_steps=settings["max_steps"],
        num_envs=cfg.num_envs,
        hidden=tuple(recipe["hidden"]),
        device=cfg.device,
        seed=cfg.seed,
        threads=recipe["threads"],
        total_env_steps=recipe["budget"],
        buffer_size=recipe["budget"] + cfg.num_envs,  # never wraps: the replay buffer keeps every transition
        checkpoint_every=0,
        save_replay=True,
        out=str(out),
        verbose=False,
    )


def _evaluate_until_target(
    cfg: BehaviourConfig,
    ds: Dataset,
    recipe: dict[str, Any],
    dqn_cfg,
    normalizer: Normalizer,
    refs: dict[str, float],
    pairs: np.ndarray,
    history: list[list[float]],
    say,
):
    """The training callback: every ``eval_every`` env steps, the normalised score of the epsilon-greedy agent
    (appended to ``history``); true, so training stops, once it reaches the recipe's target."""
    eval_spec = BehaviourSpec("epsilon-greedy", epsilon=recipe["epsilon"])
    next_eval = [recipe["eval_every"]]

    def callback(q, env_steps: int, train_s: float) -> bool:
        if env_steps < next_eval[0]:
            return False
        while next_eval[0] <= env_steps:
            next_eval[0] += recipe["eval_every"]
        greedy = Policy(q, dqn_cfg, normalizer, cfg.obs, {})
        bp = BehaviourPolicy(
            q=None, config=None, normalizer=normalizer, obs_preset=cfg.obs, meta={}, spec=eval_spec,
            seed=recipe["eval_seed"], greedy=greedy,
        )  # fmt: skip
        spl = metrics_from_rollouts(rollout(bp, ds, pairs, device=cfg.device)).spl
        score = normalized(spl, refs)
        history.append([int(env_steps), round(float(train_s), 3), spl, score])
        if cfg.verbose:
            say(f"  medium agent: {env_steps:>7d} env steps, {train_s:6.1f} s, normalised score {score:6.1f}")
        return score >= recipe["target"]

    return callback


def _check_reached(ds: Dataset, recipe: dict[str, Any], history: list[list[float]], result) -> None:
    """Refuse an agent whose budget ran out before an evaluation reached the target: it is not the recipe's agent."""
    if not history or history[-1][3] < recipe["target"]:
        best = max((h[3] for h in history), default=float("nan"))
        raise ConfigError(
            f"the medium agent reached a normalised score of {best:.1f} at most in {result.env_steps} env steps "
            f"on {ds.name}, short of the target {recipe['target']:g}",
            hint="raise --medium-budget, or lower --medium-target",
        )


def _medium_record(
    key: str, inputs: dict[str, Any], result, refs: dict[str, float], history: list[list[float]], checkpoint: Path
) -> dict[str, Any]:
    """``medium.json``: the stop (the last evaluation), the training's totals and every evaluation."""
    recipe = inputs["medium"]
    _, _, spl, score = history[-1]
    return {
        "key": key,
        "inputs": inputs,
        "stopped_at_env_steps": int(result.env_steps),
        "updates": int(result.updates),
        "episodes": int(result.episodes),
        "train_s": float(result.wall_s),
        "spl": float(spl),
        "score": float(score),
        "target": float(recipe["target"]),
        "tolerance": MEDIUM_TOLERANCE,
        "within_tolerance": bool(score - recipe["target"] <= MEDIUM_TOLERANCE),
        "references": refs,
        "evaluations": len(history),
        "history": [{"env_steps": h[0], "train_s": h[1], "spl": h[2], "score": h[3]} for h in history],
        "checkpoint_sha256": sha256_file(checkpoint),
        "last_sha256": sha256_file(checkpoint.parent / "last.pt"),
    }


def _install(record: dict[str, Any], out: Path, dest: Path, stage: Path) -> None:
    """Write the record and move the whole run into the cache folder, so a reader finds it whole or not at all."""
    write_atomic(out / MEDIUM_RECORD, json.dumps(record, indent=2, sort_keys=True) + "\n")
    dest.parent.mkdir(parents=True, exist_ok=True)
    if dest.exists():  # damaged: moved into the stage, removed with it
        os.rename(dest, stage / "damaged")
    shutil.move(str(out), dest)


def _say_stopped(key: str, record: dict[str, Any], say) -> None:
    """Where training stopped, and whether the agent overshot the target by more than the tolerance."""
    note = "" if record["within_tolerance"] else f" (more than {MEDIUM_TOLERANCE:g} past the target)"
    say(
        f"medium agent {key}: stopped at {record['stopped_at_env_steps']} env steps ({record['train_s']:.1f} s), "
        f"normalised score {record['score']:.1f}{note}"
    )


def resolve_spec(cfg: BehaviourConfig, ds: Dataset, *, agent: MediumAgent | None = None, say=print) -> BehaviourSpec:
    """``cfg``'s behaviour spec, with the medium agent's checkpoint filled in when the behaviour acts with it (trained
    or reused by :func:`medium_agent`), so :func:`~dtradar_rl.offline.behaviours.behaviour_policy` and
    :func:`~dtradar_rl.offline.collection.roll` can act with it."""
    spec = cfg.spec()
    if "medium" not in spec.used:
        return spec
    agent = agent or medium_agent(cfg, ds, say)
    return replace(spec, medium_checkpoint=str(agent.checkpoint))


__all__ = [
    "MEDIUM_AGENTS",
    "cached_agent_problem",
    "MEDIUM_RECORD",
    "MediumAgent",
    "medium_agent",
    "medium_agent_dir",
    "medium_key_inputs",
    "resolve_spec",
]
