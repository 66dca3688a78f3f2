"""Logged offline-RL datasets: log a behaviour policy on a twin into the store, and open the result as Minari or d3rlpy.

    from dtradar_rl.offline.logged import LogConfig, log_dataset
    from dtradar_rl.offline.formats import to_mdp_dataset, export_minari
    logged = log_dataset(LogConfig(scene="cubicle", behaviour="noisy-shortest"))   # cubicle/blueprint/noisy-shortest
    logged = dtradar_data.load("cubicle/blueprint/noisy-shortest")                 # the same, from the store
    mdp = to_mdp_dataset(logged)            # d3rlpy MDPDataset, every logged transition kept and aligned
    minari_id = export_minari(logged)       # "dtradar/cubicle-blueprint-noisy-shortest-v0" in <data root>/minari

Storage, names, versions and cards are :mod:`dtradar_data.store.logged` (no torch there); the behaviour
policies are :mod:`dtradar_rl.offline.behaviours` and the one rollout engine :mod:`dtradar_rl.offline.collection`. This
module joins them: :func:`log_dataset` computes the version from the logging inputs *first*, so logging the same name
with the same settings again only loads the stored version (and replaces it when it is damaged). Two processes logging
the same version take turns (the second says what it waits for, then reuses the first's); staging folders that a
killed run left in ``<root>/work`` are removed first.

Its formats (Parquet in the store, Minari, d3rlpy) are :mod:`dtradar_rl.offline.formats`.

**Dataset families** (D4RL's names, :data:`~dtradar_rl.offline.behaviours.FAMILIES`): ``random``, ``expert``,
``medium``, ``medium-replay`` and ``mixed`` are behaviours like the others (``--behaviour medium``);
:func:`log_families` (``--behaviour all``) logs all five on a twin. The medium agent is an online DQN trained once per
recipe by :func:`medium_agent` and cached under ``<root>/logged/<scene>/<variant>/medium/agents/<key>/`` (``model.pt``,
``last.pt`` with its replay buffer, ``medium.json``), where ``key`` hashes the twin, the recipe, the seed, the logging
settings and the library versions; ``medium``, ``medium-replay`` and ``mixed`` of the same settings share it.

**Normalised score** (:mod:`dtradar_rl.evaluation.normalized`): every logged version's ``meta.json`` and card give it
twice: the behaviour itself rolled out on the twin's seeded evaluation pairs (``score.policy``; absent for
``medium-replay``, which is no single policy), and the SPL of its logged episodes (``score.episodes``; see
:func:`~dtradar_rl.evaluation.normalized.logged_episodes_spl` for which episodes count).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core import layout as P
from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError
from dtradar_data.core.files import sha256_file, waiting_lock, write_atomic
from dtradar_data.store.logged import (
    LOGGED_LIBRARIES,
    MINARI_ENV,
    LoggedDataset,
    clean_logged_stages,
    load_logged,
    local_versions,
    logged_dir,
    logged_version,
    logging_inputs,
    logging_lock,
    minari_root,
    parse_logged_id,
    table_digest,
    transitions_table,
    write_logged,
)
from dtradar_data.store.logged.staging import held_stage
from dtradar_data.store.versions import library_versions, version_id
from dtradar_rl.agents.checkpoints import CHECKPOINT_FORMAT, read_checkpoint
from dtradar_rl.agents.policy import Policy
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.evaluation.normalized import (
    DEFAULT_PAIRS,
    DEFAULT_SEED,
    METRIC,
    logged_episodes_spl,
    normalized,
    policy_score,
    reference_scores,
)
from dtradar_rl.offline.behaviours import (
    ALL,
    FAMILIES,
    MEDIUM_TOLERANCE,
    OGBENCH_FAMILIES,
    BehaviourConfig,
    BehaviourPolicy,
    BehaviourSpec,
    behaviour_policy,
)
from dtradar_rl.offline.collection import replay, roll
from dtradar_rl.offline.formats import export_minari
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.grid_mdp import GridMDP
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.twins import load_dataset


@dataclass(frozen=True)
class LogConfig(BehaviourConfig):
    """Log a behaviour policy on a twin into the store as a versioned, carded dataset
    ``<scene>/<variant>/<name>``."""

    behaviour: str = "noisy-shortest"
    """behaviour policy: random, noisy-shortest, epsilon-greedy (a DQN checkpoint) or mixture (see --components); or a
    dataset family: D4RL's random, expert, medium, medium-replay, mixed, OGBench's navigate, stitch, explore; or all
    (the eight families)"""
    name: str = ""
    """third part of the dataset name (default: the behaviour)"""
    steps: int = 100_000
    """environment steps to log (all robots together; rounded up to whole steps of num-envs robots)"""
    minari: bool = True
    """also write the Minari copy (needs the [offline] extra: pip install minari)"""

    @property
    def logged_name(self) -> str:
        return f"{self.scene}/{self.variant}/{self.name or self.behaviour}"

    def families(self) -> list[LogConfig]:
        """``--behaviour all``: one config per dataset family (D4RL's, then OGBench's), else ``[self]``."""
        if self.behaviour != ALL:
            return [self]
        return [replace(self, behaviour=f, name="") for f in (*FAMILIES, *OGBENCH_FAMILIES)]

    def validate(self) -> LogConfig:
        if self.behaviour == ALL:
            if self.name:
                raise ConfigError(
                    "--name names one dataset; --behaviour all logs one per family, each under its family's name"
                )
            for c in self.families():
                c.validate()
            return self
        super().validate()
        if self.behaviour != "medium-replay":  # medium-replay holds what the medium run collected: no --steps
            self.check_at_least(1, "steps")
        parse_logged_id(self.logged_name)  # the name must fit the grammar
        return self


def parent_version(ds: Dataset) -> str:
    """The parent's stored content version, or a hash of its table (synthetic twins have no stored version)."""
    return ds.version or table_digest(ds.table)


def settings_of(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    max_steps = cfg.max_steps or GridMDP.from_dataset(ds).max_steps
    return {
        "num_envs": cfg.num_envs,
        "obs": cfg.obs,
        "reward": cfg.reward,
        "max_steps": int(max_steps),
        "device_kind": "cuda" if cfg.device.startswith("cuda") else "cpu",
    }


def log_inputs(cfg: LogConfig, ds: Dataset) -> dict[str, Any]:
    return logging_inputs(
        parent=ds.name,
        parent_version=parent_version(ds),
        behaviour=cfg.spec().to_dict(),
        steps=0 if cfg.behaviour == "medium-replay" else cfg.steps,
        seed=cfg.seed,
        settings=settings_of(cfg, ds),
    )


def _stored(lid, version: str, say) -> LoggedDataset | None:
    """The stored ``lid@version`` if it loads and verifies; None when absent or damaged (then logged again)."""
    if version not in local_versions(lid, damaged=True):
        return None
    try:
        return load_logged(lid, version)
    except (CorruptDatasetError, SchemaMismatchError) as exc:
        say(f"{lid.name}@{version} is stored but damaged ({exc.message}): logging it again")
        return None


def log_families(cfg: LogConfig, dataset: Dataset | None = None) -> dict[str, LoggedDataset]:
    """Every dataset family (``cfg.behaviour`` ``all``; else just ``cfg.behaviour``) logged on the twin with ``cfg``'s
    settings, by :func:`log_dataset`; ``{family: dataset}``. The medium agent is trained once for all three that
    use it."""
    cfg = cfg.validate()
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    return {c.behaviour: log_dataset(c, ds) for c in cfg.families()}


def log_dataset(cfg: LogConfig, dataset: Dataset | None = None) -> LoggedDataset:
    """Log ``cfg.behaviour`` on ``cfg.dataset_name`` into the store (or reuse the stored version of the same inputs;
    a damaged one is logged again), write the Minari copy when ``cfg.minari``, and return the loaded dataset."""
    if cfg.behaviour == ALL:
        raise ConfigError("log_dataset logs one behaviour", hint="use log_families for --behaviour all")
    cfg = cfg.validate()
    import torch

    torch.set_num_threads(cfg.threads or auto_threads())
    say = print if cfg.verbose else (lambda *a, **k: None)
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    inputs = log_inputs(cfg, ds)
    version = logged_version(inputs)
    lid = parse_logged_id(cfg.logged_name)
    clean_logged_stages()
    with logging_lock(lid, version):
        logged = _stored(lid, version, say)
        if logged is not None:
            say(f"{lid.name}@{logged.tag} ({version}) is already logged with these settings: reused")
        else:
            logged = _log(cfg, ds, lid, inputs, say)
    if cfg.minari:
        mid = export_minari(logged)
        say(f"Minari copy: {logged.minari_path} (load: {MINARI_ENV}={minari_root()} minari.load_dataset({mid!r}))")
    return logged


def _log(cfg: LogConfig, ds: Dataset, lid, inputs: dict[str, Any], say) -> LoggedDataset:
    """Roll the behaviour out (or replay the medium run's buffer), store the table as a version and load it back."""
    normalizer = Normalizer.fit(ds)
    settings = inputs["settings"]
    agent = medium_agent(cfg, ds, say) if cfg.spec().needs_medium else None
    spec = resolve_spec(cfg, ds, agent=agent)
    env_kw = dict(
        num_envs=cfg.num_envs,
        obs=cfg.obs,
        normalizer=normalizer,
        reward=cfg.reward,
        max_steps=settings["max_steps"],
        seed=cfg.seed,
        device=cfg.device,
    )
    if cfg.behaviour == "medium-replay":
        state = read_checkpoint(agent.last, (CHECKPOINT_FORMAT,), what="medium agent's training state (last.pt)")
        r = replay(ds, state["replay"], **env_kw)
        if r.stats["steps"] != agent.record["stopped_at_env_steps"]:
            raise CorruptDatasetError(
                f"{agent.last} holds {r.stats['steps']} transitions, its run collected "
                f"{agent.record['stopped_at_env_steps']}",
                hint=f"remove {agent.path} and log again (the agent is retrained)",
            )
    else:
        r = roll(ds, spec, steps=cfg.steps, **env_kw)
    c = r.columns
    table = transitions_table(
        episode=c["episode"],
        step=c["step"],
        obs=c["obs"],
        action=c["action"],
        reward=c["reward"],
        next_obs=c["next_obs"],
        terminated=c["terminated"],
        truncated=c["truncated"],
        robot=c["robot"],
        cell=c["cell"],
        target=c["target"],
        component=c["component"],
    )
    names = list(build_observations(ds, cfg.obs, normalizer).names)
    meta = {
        "behaviour_text": spec.describe(),
        "normalizer": normalizer.to_dict(),
        "observations": {"preset": cfg.obs, "names": names},
        "stats": {"rollout": r.stats},
        "score": behaviour_score(cfg, ds, spec, c, settings["max_steps"]),
    }
    if cfg.behaviour in FAMILIES or cfg.behaviour in OGBENCH_FAMILIES:
        meta["family"] = cfg.behaviour
    if agent is not None:
        meta["medium_agent"] = agent.summary()
    version, _ = write_logged(lid, inputs, table, meta)
    logged = load_logged(lid, version)
    s = logged.meta["stats"]
    pol = meta["score"].get("policy") or {}
    say(
        f"logged {lid.name}@{logged.tag} ({version}): {s['steps']} steps, {s['episodes']} episodes, behaviour "
        f"success {s['success_rate']:.3f}, mean return {s['mean_return']:.2f} in {r.stats['wall_s']:.1f} s; "
        + (f"normalised score {pol['normalized']:.1f} (rolled out), " if pol else "")
        + f"{meta['score']['episodes']['normalized']:.1f} (logged episodes)"
    )
    return logged


# -- the normalised score of a logged dataset ---------------------------------------------------------------------
def behaviour_score(
    cfg: LogConfig, ds: Dataset, spec: BehaviourSpec, columns: dict[str, np.ndarray], max_steps: int
) -> dict[str, Any]:
    """The normalised score of a log (``meta["score"]``): ``policy``, the behaviour rolled out on the twin's seeded
    evaluation pairs with the twin's default step limit (None for ``medium-replay``, which is no single policy), and
    ``episodes``, the SPL of the logged episodes that started at least ``max_steps`` (the log's step limit) before the
    end of their robot's log (:func:`~dtradar_rl.evaluation.normalized.logged_episodes_spl`), both normalised by the
    same references."""
    refs = reference_scores(ds, pairs=DEFAULT_PAIRS, seed=DEFAULT_SEED, device=cfg.device)
    ep = logged_episodes_spl(
        ds,
        episode=columns["episode"],
        robot=columns["robot"],
        cell=columns["cell"],
        action=columns["action"],
        target=columns["target"],
        terminated=columns["terminated"],
        max_steps=max_steps,
    )
    ep["normalized"] = normalized(ep["spl"], refs) if ep["episodes"] else float("nan")
    pol = None
    if spec.used:
        bp = behaviour_policy(spec, ds, obs=cfg.obs, seed=DEFAULT_SEED, device=cfg.device)
        pol = policy_score(bp, ds, pairs=DEFAULT_PAIRS, seed=DEFAULT_SEED, device=cfg.device)
        pol.pop("references")
    return {
        "metric": METRIC,
        "pairs": DEFAULT_PAIRS,
        "seed": DEFAULT_SEED,
        "references": refs,
        "definition": "100 * (SPL - random) / (expert - random): 0 = uniformly random moves, 100 = breadth-first "
        "shortest-path moves, on the twin's seeded evaluation pairs (dtradar_rl.evaluation.normalized)",
        "policy": pol,
        "episodes": ep,
    }


# -- the medium agent ------------------------------------------------------------------------------------------------
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
        "settings": settings_of(cfg, ds),
        "library_versions": library_versions(LOGGED_LIBRARIES),
    }


def medium_agent_dir(cfg: BehaviourConfig, key: str) -> Path:
    return logged_dir(parse_logged_id(f"{cfg.scene}/{cfg.variant}/medium")) / MEDIUM_AGENTS / key


def _stored_agent(path: Path, key: str) -> MediumAgent | None:
    try:
        record = json.loads((path / MEDIUM_RECORD).read_text())
        agent = MediumAgent(path, record)
        if record.get("key") == key and agent.last.is_file():
            if sha256_file(agent.checkpoint) == record.get("checkpoint_sha256"):
                return agent
    except (OSError, ValueError):
        pass
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
        agent = _stored_agent(path, key)
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

    from dtradar_rl.train.config import config_for
    from dtradar_rl.train.dqn import train

    recipe, settings = inputs["medium"], inputs["settings"]
    refs = reference_scores(ds, pairs=recipe["pairs"], seed=recipe["eval_seed"], device=cfg.device)
    normalizer = Normalizer.fit(ds)
    pairs = sample_eval_pairs(ds, recipe["pairs"], recipe["eval_seed"])
    eval_spec = BehaviourSpec("epsilon-greedy", epsilon=recipe["epsilon"])
    history: list[list[float]] = []
    next_eval = [recipe["eval_every"]]
    say(
        f"training the medium agent {key} on {ds.name} ({recipe['preset']} DQN, seed {cfg.seed}, up to "
        f"{recipe['budget']} env steps, until its normalised score reaches {recipe['target']:g})"
    )
    threads = torch.get_num_threads()
    with held_stage(P.work_root(), _AGENT_STAGE) as stage:
        out = stage / "run"
        dqn_cfg = config_for(
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

        try:
            result = train(dqn_cfg, ds, normalizer=normalizer, callback=callback)
        finally:
            torch.set_num_threads(threads)
        if not history or history[-1][3] < recipe["target"]:
            best = max((h[3] for h in history), default=float("nan"))
            raise ConfigError(
                f"the medium agent reached a normalised score of {best:.1f} at most in {result.env_steps} env steps "
                f"on {ds.name}, short of the target {recipe['target']:g}",
                hint="raise --medium-budget, or lower --medium-target",
            )
        steps, _, spl, score = history[-1]
        record = {
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
            "checkpoint_sha256": sha256_file(out / "model.pt"),
        }
        write_atomic(out / MEDIUM_RECORD, json.dumps(record, indent=2, sort_keys=True) + "\n")
        dest.parent.mkdir(parents=True, exist_ok=True)
        if dest.exists():  # damaged: moved into the stage, removed with it
            os.rename(dest, stage / "damaged")
        shutil.move(str(out), dest)
    note = "" if record["within_tolerance"] else f" (more than {MEDIUM_TOLERANCE:g} past the target)"
    say(
        f"medium agent {key}: stopped at {record['stopped_at_env_steps']} env steps ({record['train_s']:.1f} s), "
        f"normalised score {score:.1f}{note}"
    )
    return MediumAgent(dest, record)


def resolve_spec(cfg: BehaviourConfig, ds: Dataset, *, agent: MediumAgent | None = None, say=print) -> BehaviourSpec:
    """``cfg``'s behaviour spec, with the medium agent's checkpoint filled in when the behaviour acts with it (trained
    or reused by :func:`medium_agent`), so :func:`~dtradar_rl.offline.behaviours.behaviour_policy` and
    :func:`~dtradar_rl.offline.collection.roll` can act with it."""
    spec = cfg.spec()
    if "medium" not in spec.used:
        return spec
    agent = agent or medium_agent(cfg, ds, say)
    return replace(spec, medium_checkpoint=str(agent.checkpoint))


def check_compatible(logged: LoggedDataset, cfg: TwinConfig, ds: Dataset) -> None:
    """:class:`SchemaMismatchError` when ``logged`` was not logged on ``ds`` with ``cfg``'s observation preset (the
    trainer would otherwise learn from features another normaliser or preset produced)."""
    meta = logged.meta
    problems = []
    if meta.get("parent") != ds.name:
        problems.append(f"it was logged on {meta.get('parent')!r}, the trainer uses {ds.name!r}")
    elif meta.get("parent_version") != parent_version(ds):
        problems.append(
            f"it was logged on version {meta.get('parent_version')} of {ds.name}, the trainer loaded "
            f"{parent_version(ds)}"
        )
    preset = (meta.get("observations") or {}).get("preset")
    if preset != cfg.obs:
        problems.append(f"its observation preset is {preset!r}, the trainer's {cfg.obs!r}")
    stored = meta.get("normalizer")
    if stored and not problems:
        fitted = Normalizer.fit(ds)
        if not np.allclose(stored["mean"], fitted.mean, rtol=1e-5) or not np.allclose(
            stored["std"], fitted.std, rtol=1e-5
        ):
            problems.append("its feature normaliser differs from the one fitted on the twin")
    if problems:
        raise SchemaMismatchError(
            f"logged dataset {logged.name}@{logged.version} does not fit: " + "; ".join(problems),
            hint=f"train with --scene/--variant/--obs of the log (parent {meta.get('parent')}, "
            f"preset {preset}), or log again on this twin",
        )


__all__ = [
    "LogConfig",
    "MediumAgent",
    "behaviour_score",
    "check_compatible",
    "log_dataset",
    "log_families",
    "log_inputs",
    "medium_agent",
    "medium_key_inputs",
    "parent_version",
    "resolve_spec",
    "settings_of",
]
