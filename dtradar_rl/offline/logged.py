"""Logged offline-RL datasets: log a behaviour policy on a twin into the store, and open the result as Minari or d3rlpy.

    from dtradar_rl.offline.logged import LogConfig, log_dataset
    from dtradar_rl.offline.formats import to_mdp_dataset
    from dtradar_rl.offline.minari_copy import check_minari_free, export_minari
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
recipe and cached (:mod:`dtradar_rl.offline.medium_agent`); ``medium``, ``medium-replay`` and ``mixed`` of the same
settings share it. What ties a log to its twin (parent version, settings, the trainer's check) is
:mod:`dtradar_rl.offline.log_settings`.

**Normalised score** (:mod:`dtradar_rl.evaluation.normalized`): every logged version's ``meta.json`` and card give it
twice: the behaviour itself rolled out on the twin's seeded evaluation pairs (``score.policy``; absent for
``medium-replay``, which is no single policy), and the SPL of its logged episodes (``score.episodes``; see
:func:`~dtradar_rl.evaluation.normalized.logged_episodes_spl` for which episodes count).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Annotated, Any

import numpy as np
import tyro

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import CorruptDatasetError, SchemaMismatchError
from dtradar_data.core.files import human_size
from dtradar_data.core.layout import writable_data_root
from dtradar_data.core.machine import available_memory
from dtradar_data.store import read_refs
from dtradar_data.store.logged import (
    MINARI_ENV,
    TRANSITIONS_FILE,
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
    read_meta,
    refs_path,
    transitions_table,
    write_logged,
)
from dtradar_rl.agents.checkpoints import CHECKPOINT_FORMAT, read_checkpoint
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
    OGBENCH_FAMILIES,
    BehaviourConfig,
    BehaviourSpec,
    behaviour_policy,
)
from dtradar_rl.offline.collection import replay, roll, rollout_bytes, rollout_steps
from dtradar_rl.offline.log_settings import parent_version, settings_of
from dtradar_rl.offline.medium_agent import medium_agent, resolve_spec
from dtradar_rl.offline.minari_copy import check_minari_free, export_minari
from dtradar_rl.offline.moving_logs import check_moving_log, moving_meta
from dtradar_rl.task.config import DEFAULT_IN_HELP, ConfigError
from dtradar_rl.task.observations import Normalizer, build_observations, obs_dim
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.sensing import HONEST_PRESET, honest_dim, honest_names, sensing_for
from dtradar_rl.task.twins import load_dataset


class LogTooLargeError(ConfigError):
    """A log whose rollout would not fit in the memory this machine has (every step is held until it is stored),
    refused before anything is rolled out; the message gives the size, what is available and the --steps that fit."""


@dataclass(frozen=True)
class LogConfig(BehaviourConfig):
    """Log a behaviour policy on a twin into the store as a versioned, carded dataset
    ``<scene>/<variant>/<name>``.

    The shared fields are declared again for the help text of ``log``, which trains nothing (their base docstrings
    speak of training); ``out`` is hidden: a log goes into the store, under its name, not into a run folder."""

    scene: str = "cubicle"
    """scene to log on; the twin is <scene>/<variant> (synthetic = a 42x18 stand-in, no ray tracer)"""
    variant: str = "blueprint"
    """twin to log on; the dataset is <scene>/<variant>/<name>"""
    seed: int = 0
    """seed of the robots' starts and targets and of the behaviour's random moves (with medium, medium-replay and mixed
    also of the medium agent's training); part of the dataset's version"""
    out: tyro.conf.Suppress[str] = ""
    reward: str = "geodesic"
    """reward logged with each transition: paper (exact), scaled, euclidean or geodesic (shaped; see
    dtradar_rl.task.rewards)"""
    num_envs: int = 256
    """robots stepped together while logging (in a mixture, robot i acts with component i mod k)"""
    hidden: tuple[int, ...] = (256, 256)
    """medium, medium-replay, mixed: sizes of the medium agent's dense ReLU hidden layers (part of its recipe and so
    of the dataset's version; the other behaviours have no network of their own)"""
    device: str = "cpu"
    """torch device (cpu, cuda, cuda:1) the robots are stepped on while logging and scoring, and the medium agent
    trains on (medium, medium-replay, mixed)"""
    behaviour: str = "noisy-shortest"
    """behaviour policy: random, noisy-shortest, epsilon-greedy (a DQN checkpoint) or mixture (see --components); or a
    dataset family: D4RL's random, expert, medium, medium-replay, mixed, OGBench's navigate, stitch, explore; or all
    (the eight families)"""
    name: Annotated[str, DEFAULT_IN_HELP] = ""
    """third part of the dataset name (default: the behaviour, followed by the --sensing when it is honest)"""
    steps: int = 100_000
    """environment steps to log (all robots together; rounded up to whole steps of num-envs robots)"""
    minari: bool = True
    """also write the Minari copy (needs the [offline] extra: pip install minari)"""
    minari_memory: bool = False
    """also write a second Minari copy, <id>-memory, whose observations carry the default agent's memory window and
    whose recover_environment() is the memory env (the neighbors preset; off by default: 3x the size)"""

    @property
    def logged_name(self) -> str:
        """``<scene>/<variant>/<name>``; by default the name is the behaviour, followed by the sensing when the log
        records an honest one (``expert-radio``: a name says how the data was collected and what it holds)."""
        default = f"{self.behaviour}-{self.sensing}" if self.honest else self.behaviour
        return f"{self.scene}/{self.variant}/{self.name or default}"

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
        if self.minari_memory and not self.minari:
            raise ConfigError(
                "--minari-memory writes a second Minari copy, and --no-minari writes none", hint="drop one"
            )
        if self.minari_memory and self.honest:
            raise ConfigError(
                f"--minari-memory adds the privileged agents' memory window, and this log records --sensing "
                f"{self.sensing}",
                hint="drop --minari-memory (an honest log's Minari copy holds what the robot's own sensors read)",
            )
        if self.minari_memory and self.obs != "neighbors":
            raise ConfigError(
                "--minari-memory: the memory window extends the neighbors observation, and this log observes "
                f"{self.obs}",
                hint="log with --obs neighbors (the default agent's preset), or drop --minari-memory",
            )
        if self.behaviour != "medium-replay":  # medium-replay holds what the medium run collected: no --steps
            self.check_at_least(1, "steps")
            self.check_memory()
        parse_logged_id(self.logged_name)  # the name must fit the grammar
        return self

    def check_memory(self, transmitters: int = 1) -> None:
        """:class:`LogTooLargeError` when rolling out ``--steps`` (observations of ``--obs`` on a twin of
        ``transmitters``; 1, the narrowest, before the twin is loaded) needs more memory than this machine has
        available (:func:`~dtradar_rl.offline.collection.rollout_bytes`); not checked where the system does not say."""
        width = honest_dim(transmitters) if self.honest else obs_dim(self.obs, transmitters)
        what = f"--sensing {self.sensing}" if self.honest else self.obs
        need, have = rollout_bytes(self.steps, self.num_envs, width), available_memory()
        if have is None or need <= have:
            return
        per_step = rollout_bytes(self.num_envs, self.num_envs, width) // self.num_envs
        fit = have // per_step // self.num_envs * self.num_envs
        raise LogTooLargeError(
            f"--steps {self.steps}: logging {rollout_steps(self.steps, self.num_envs):,} steps of {width}-column "
            f"{what} observations holds about {human_size(need)} in memory ({per_step} bytes a step: "
            "its observation, next observation and other columns, held twice while they are stacked); this machine "
            f"has {human_size(have)} available",
            hint=f"log fewer --steps (about {fit:,} fit now)" if fit else "free memory (other processes) and log again",
        )


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
    writable_data_root()  # a read-only data root is refused before the twin is loaded, a family rolled out
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    check_moving_log(cfg, ds)
    check_minari_copies(cfg.families(), ds)  # all of them before the first family is logged
    return {c.behaviour: log_dataset(c, ds) for c in cfg.families()}


def check_minari_copies(cfgs: list[LogConfig], ds: Dataset) -> None:
    """Refuse, before anything is logged or stored, a log (of those of ``cfgs`` that write a Minari copy) whose copy
    could not be written: its Minari folder (``dtradar/...-v<N>``, ``N`` the tag the version has or will get) holds
    another data root's copy or a dataset dtradar did not write. Found only at the copy, the version would be stored
    and the command fail, half done."""
    for c in cfgs:
        if not c.minari:
            continue
        version = logged_version(log_inputs(c, ds))
        lid = parse_logged_id(c.logged_name)
        refs = read_refs(refs_path(lid))
        tag, sha = refs.tag_of(version), None
        if tag is not None:  # stored: its copy must hold this very transitions file
            try:
                sha = read_meta(logged_dir(lid) / version)["files"][TRANSITIONS_FILE]["sha256"]
            except (CorruptDatasetError, KeyError, TypeError):
                sha = None  # damaged: logged again, its transitions unknown yet
        for senses in ("none", "memory") if c.minari_memory else ("none",):
            check_minari_free(lid.name, version, tag or refs.next_tag(), sha, senses=senses)


def log_dataset(cfg: LogConfig, dataset: Dataset | None = None) -> LoggedDataset:
    """Log ``cfg.behaviour`` on ``cfg.dataset_name`` into the store (or reuse the stored version of the same inputs;
    a damaged one is logged again), write the Minari copy when ``cfg.minari``, and return the loaded dataset."""
    if cfg.behaviour == ALL:
        raise ConfigError("log_dataset logs one behaviour", hint="use log_families for --behaviour all")
    cfg = cfg.validate()
    # the lock, the version and its Minari copy are written into the data root: a read-only one (a shared mirror, a
    # container image) is refused here, not with a raw PermissionError at the lock
    writable_data_root()
    import torch

    torch.set_num_threads(cfg.threads or auto_threads())
    say = print if cfg.verbose else (lambda *a, **k: None)
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    check_moving_log(cfg, ds)
    if cfg.behaviour != "medium-replay":
        cfg.check_memory(ds.transmitters)  # the twin's own observation width, wider with each transmitter
    check_minari_copies([cfg], ds)
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
    if cfg.minari_memory:
        mid = export_minari(logged, senses="memory")
        say(f"Minari copy with the memory window: {minari_root() / mid} (minari.load_dataset({mid!r}))")
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
        r = roll(ds, spec, steps=cfg.steps, sensing=cfg.sensing, sensing_noise=cfg.sensing_noise, **env_kw)
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
    meta = {
        "behaviour_text": spec.describe(),
        "normalizer": normalizer.to_dict(),
        "observations": observations_meta(cfg, ds, normalizer),
        "stats": {"rollout": r.stats},
        "score": behaviour_score(cfg, ds, spec, c, settings["max_steps"]),
    }
    if ds.is_moving:  # the snapshot of every step, which the table has no column for
        meta["moving"] = moving_meta(ds, c)
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


def observations_meta(cfg: LogConfig, ds: Dataset, normalizer: Normalizer) -> dict[str, Any]:
    """``meta["observations"]``: what a logged step's ``obs`` holds. ``preset`` is the privileged preset's name, or
    ``honest`` with the ``sensing``, its receiver ``noise`` and a line on what the robot observes."""
    sensing = sensing_for(cfg.sensing)
    if sensing.privileged:
        names = list(build_observations(ds, cfg.obs, normalizer).names)
        return {"preset": cfg.obs, "sensing": sensing.name, "observes": sensing.describe(), "names": names}
    return {
        "preset": HONEST_PRESET,
        "sensing": sensing.name,
        "noise": cfg.sensing_noise,
        "observes": sensing.describe(),
        "names": list(honest_names(ds.transmitters)),
    }


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
        snapshot=columns.get("snapshot"),  # a moving twin's: the SPL in time, as evaluation measures it there
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


__all__ = [
    "LogConfig",
    "LogTooLargeError",
    "behaviour_score",
    "check_minari_copies",
    "log_dataset",
    "log_families",
    "log_inputs",
]
