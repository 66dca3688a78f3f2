"""Offline-RL baselines with d3rlpy: log a behaviour policy's transitions on a twin, train on them, evaluate.

    from dtradar_rl.offline.trainer import OfflineConfig, train_offline
    result = train_offline(OfflineConfig(scene="cubicle", algorithm="cql"))
    result.model      # runs/cubicle/offline/cql/model.d3, with config.json, dataset.h5, results.{json,md} beside it

Three stages, each usable on its own:

1. **Logging** (:func:`roll_behaviour`, :func:`log_transitions`). ``num_envs`` robots act with a *behaviour policy*
   in the batched environment (:class:`dtradar_rl.envs.batched.BatchedNavEnv`, same observations and rewards as online
   DQN) until about ``transitions`` steps are logged. ``noisy-shortest`` takes, with probability
   ``shortest_prob``, a breadth-first shortest-path move (ties broken at random, distances from
   :meth:`GridMDP.bfs_distances_many <dtradar_rl.task.mdp.GridMDP.bfs_distances_many>` on the logged twin) and otherwise
   a uniformly random move; ``random`` always moves at random. The interleaved ``[step, robot]`` streams are
   reordered robot by robot, so every episode is contiguous and ends in exactly one flag: ``terminal`` (target
   reached) or ``timeout`` (the step limit, or the logging budget ending mid-episode; an unfinished tail shorter
   than two steps carries no transition and is dropped). ``timeout`` is set only where ``terminal`` is not:
   d3rlpy 2.8.1 asserts on a step flagged both. The result is a d3rlpy ``MDPDataset``; it is also written as
   ``dataset.h5`` (d3rlpy ``dump``; reload with ``ReplayBuffer.load(f, InfiniteBuffer())``) and, cell by cell,
   as ``transitions.npz`` (cells, targets, actions, rewards, flags, robot ids).
2. **Training** (:func:`train_offline`): d3rlpy's config → ``create`` → ``fit`` with ``DiscreteCQL``,
   ``DiscreteBCQ``, ``DiscreteBC`` or ``DQN`` (:data:`ALGORITHMS`), seeded with ``d3rlpy.seed``, d3rlpy's own
   file logging and progress bars off (our ``losses.csv`` holds the per-epoch losses). d3rlpy's defaults are
   tuned for Atari (learning rate 6.25e-5, target sync every 8000 updates, γ = 0.99); here γ, learning rate,
   target interval and hidden sizes come from :class:`OfflineConfig`, with defaults measured on the cubicle twin.
3. **Evaluation**: :class:`OfflinePolicy` wraps the trained algorithm as a :class:`dtradar_rl.train.dqn.Policy`, so
   :func:`dtradar_rl.evaluation.evaluate.evaluate` runs it unchanged (greedy action = ``algo.predict``). The obstacle shield of
   :meth:`Policy.act <dtradar_rl.train.dqn.Policy.act>` is reused: a vetoed greedy move is replaced by the best allowed
   one by the algorithm's action values (``predict_value``; BC: its policy logits). Blueprint → blueprint and
   blueprint → dynamic go to ``results.json`` / ``results.md`` as for ``make eval``.

``model.d3`` (``algo.save``) and ``config.json`` (this config, the feature normaliser, the observation preset and
the training dataset) make a run reloadable: :func:`load_offline_policy`.
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_data.store.transitions import LoggedDataset

from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.agents.behaviours import ShortestPathOracle
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.evaluation.evaluate import evaluate_twins, write_results
from dtradar_rl.offline.logged import (
    as_logged,
    check_compatible,
    import_d3rlpy,
    quiet_d3rlpy,
    to_mdp_dataset,
)
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.agents.policy import CheckpointError, Policy
from dtradar_rl.task.runtime import auto_threads

OFFLINE_FORMAT = "dtradar-offline/1"
#: Algorithm names and the d3rlpy config class each one uses.
ALGORITHMS: dict[str, str] = {"cql": "DiscreteCQLConfig", "bcq": "DiscreteBCQConfig", "bc": "DiscreteBCConfig",
                              "dqn": "DQNConfig", "ddqn": "DoubleDQNConfig", "nfq": "NFQConfig"}
BEHAVIOURS: tuple[str, ...] = ("noisy-shortest", "random")


@dataclass(frozen=True)
class OfflineConfig(TwinConfig):
    """Offline RL with d3rlpy: log a behaviour policy on a twin, train on the log, evaluate on the twins."""

    algorithm: str = "cql"
    """d3rlpy algorithm: cql (DiscreteCQL), bcq (DiscreteBCQ), bc (DiscreteBC), dqn (DQN, offline), ddqn
    (DoubleDQN, offline), nfq (NFQ: fitted Q, no target network)"""
    reward: str = "geodesic"
    """reward logged with each transition: paper, scaled, euclidean or geodesic (see dtradar_rl.task.mdp)"""
    behaviour: str = "noisy-shortest"
    """behaviour policy that logs the data: noisy-shortest (a breadth-first shortest-path move with probability
    shortest-prob, else a random move) or random"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the shortest-path move at each step"""
    transitions: int = 100_000
    """environment steps to log (all robots together; about, rounded up to whole steps of num-envs robots)"""
    n_steps: int = 10_000
    """d3rlpy gradient updates"""
    batch_size: int = 256
    """minibatch size of one update"""
    lr: float = 3e-4
    """Adam learning rate (d3rlpy's Atari default, 6.25e-5, is too slow for a short run)"""
    gamma: float = 0.5
    """discount factor of the Q-learning algorithms (not used by bc)"""
    target_update_interval: int = 500
    """updates between target-network syncs (cql, bcq, dqn; d3rlpy's default is 8000)"""
    bc_beta: float = 0.5
    """bc (and the imitation part of bcq): weight of the penalty on squared policy logits (d3rlpy's default)"""
    cql_alpha: float = 1.0
    """cql: weight of the conservative term"""
    bcq_flexibility: float = 0.3
    """bcq: actions whose behaviour probability is below this fraction of the likeliest are not taken"""
    eval_variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins of the scene to evaluate on after training (empty = no evaluation)"""
    pairs: int = 500
    """seeded (start, target) pairs per evaluated twin"""
    eval_seed: int = 2024
    """seed of the evaluation pairs (the same as `make eval`)"""
    shield: bool = True
    """also report the policy with the obstacle shield (neighbors preset only)"""
    save_dataset: bool = True
    """write the logged data as dataset.h5 (d3rlpy dump) and transitions.npz"""
    logged: str = ""
    """train on a stored logged dataset (e.g. cubicle/blueprint/noisy-shortest, see `dtradar_rl log`) instead of
    logging a fresh throw-away one"""
    out: str = ""
    """output directory (default runs/<scene>/offline/<algorithm>)"""

    @property
    def out_dir(self) -> Path:
        return Path(self.out or f"runs/{self.scene}/offline/{self.algorithm}")

    def validate(self) -> OfflineConfig:
        super().validate()
        check_algorithm(self.algorithm)
        if self.behaviour not in BEHAVIOURS:
            raise unknown_name("behaviour policy", self.behaviour, BEHAVIOURS)
        self.check_at_least(1, "transitions", "n_steps", "batch_size", "target_update_interval", "pairs")
        self.check_within(0, 1, "shortest_prob")
        self.check_within(0, 1, "gamma", "bcq_flexibility", open_interval=True)
        if not self.lr > 0:
            raise ConfigError(f"--lr must be > 0, got {self.lr}")
        self.check_at_least(0, "bc_beta", "cql_alpha")
        return self


def check_algorithm(name: str) -> str:
    """Return ``name`` if it is a known offline algorithm, else raise :class:`UnknownNameError` with a suggestion."""
    if name not in ALGORITHMS:
        raise unknown_name("offline algorithm", name, ALGORITHMS)
    return name


# -- 1. logging ----------------------------------------------------------------------------------------------------
@dataclass
class LoggedTransitions:
    """Logged steps, robot by robot (each robot's episodes contiguous), in d3rlpy's ``MDPDataset`` layout:
    step ``i`` is ``(observations[i], actions[i], rewards[i])``, and ``terminals[i]`` / ``timeouts[i]`` mark the
    last step of an episode (never both)."""

    observations: np.ndarray  # float32[T, obs_dim]
    actions: np.ndarray       # int64[T]
    rewards: np.ndarray       # float32[T]
    terminals: np.ndarray     # float32[T] 1 where the step reached the target
    timeouts: np.ndarray      # float32[T] 1 where the episode was cut (step limit or end of logging), not terminal
    cells: np.ndarray         # int64[T] cell the step starts from
    targets: np.ndarray       # int64[T] the episode's target cell
    robots: np.ndarray        # int64[T] which robot logged the step
    stats: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.actions.shape[0])

    @property
    def episodes(self) -> int:
        return int(self.terminals.sum() + self.timeouts.sum())

    def to_mdp_dataset(self):
        """The d3rlpy ``MDPDataset`` (discrete action space, 4 actions)."""
        d3rlpy = import_d3rlpy()
        with quiet_d3rlpy():  # "Signatures have been automatically determined."
            return d3rlpy.dataset.MDPDataset(
                observations=self.observations, actions=self.actions.astype(np.int64), rewards=self.rewards,
                terminals=self.terminals, timeouts=self.timeouts,
                action_space=d3rlpy.constants.ActionSpace.DISCRETE, action_size=4)

    def save_npz(self, path: Path) -> Path:
        """Everything but the observations (rebuilt from cells and targets by table lookup), compressed."""
        with open_atomic(Path(path), "wb") as f:
            np.savez_compressed(f, cells=self.cells, targets=self.targets, actions=self.actions, rewards=self.rewards,
                            terminals=self.terminals, timeouts=self.timeouts, robots=self.robots)
        return Path(path)


def behaviour_actions(kind: str, oracle: ShortestPathOracle, shortest_prob: float,
                      gen: torch.Generator) -> torch.Tensor:
    """Actions of the behaviour policy ``kind`` (:data:`BEHAVIOURS`) for every robot."""
    n, dev = oracle.env.num_envs, oracle.env.device
    random_actions = torch.randint(4, (n,), generator=gen, device=dev)
    if kind == "random":
        return random_actions
    if kind == "noisy-shortest":
        take = torch.rand(n, generator=gen, device=dev) < shortest_prob
        return torch.where(take, oracle.act(gen), random_actions)
    raise unknown_name("behaviour policy", kind, BEHAVIOURS)


def roll_behaviour(ds: Dataset, cfg: OfflineConfig, normalizer: Normalizer | None = None) -> LoggedTransitions:
    """Run ``cfg.behaviour`` on ``ds`` in the batched env until ``cfg.transitions`` steps are logged.

    ``normalizer`` defaults to statistics of ``ds`` (as in training)."""
    cfg.validate()
    t0 = time.perf_counter()
    normalizer = normalizer or Normalizer.fit(ds)
    env = BatchedNavEnv.from_dataset(ds, cfg.num_envs, obs=cfg.obs, normalizer=normalizer, reward=cfg.reward,
                                     max_steps=cfg.max_steps or None, device=cfg.device, seed=cfg.seed)
    oracle = ShortestPathOracle(env)
    gen = torch.Generator(device=env.device)
    gen.manual_seed(cfg.seed + 1)
    n = env.num_envs
    horizon = -(-cfg.transitions // n)
    obs_l, act_l, rew_l, term_l, trunc_l, cell_l, tgt_l = [], [], [], [], [], [], []
    obs = env.reset()
    for _ in range(horizon):
        actions = behaviour_actions(cfg.behaviour, oracle, cfg.shortest_prob, gen)
        cell_l.append(env.cell.clone())
        tgt_l.append(env.target.clone())
        _, reward, terminated, truncated, _ = env.step(actions)
        obs_l.append(obs)
        act_l.append(actions)
        rew_l.append(reward)
        term_l.append(terminated)
        trunc_l.append(truncated & ~terminated)
        env.reset_where(terminated | truncated)
        obs = env.observe()

    # [step, robot] -> [robot, step]: every robot's stream in time order, one robot after the other.
    def stack(xs):
        return torch.stack(xs, 1).cpu().numpy()

    term, trunc = stack(term_l), stack(trunc_l)
    done = term | trunc
    # The unfinished tail of every robot becomes a timeout episode; a one-step tail has no transition: dropped.
    t_idx = np.arange(horizon)
    last_done = np.where(done.any(1), horizon - 1 - np.argmax(done[:, ::-1], 1), -1)
    tail = horizon - 1 - last_done
    keep = (t_idx[None, :] <= last_done[:, None]) | (tail[:, None] >= 2)
    cut = (tail >= 2)[:, None] & (t_idx[None, :] == horizon - 1)
    timeouts = (trunc | cut) & ~term
    robots = np.broadcast_to(np.arange(n)[:, None], (n, horizon))
    logged = LoggedTransitions(
        observations=stack(obs_l)[keep].astype(np.float32), actions=stack(act_l)[keep].astype(np.int64),
        rewards=stack(rew_l)[keep].astype(np.float32), terminals=term[keep].astype(np.float32),
        timeouts=timeouts[keep].astype(np.float32), cells=stack(cell_l)[keep], targets=stack(tgt_l)[keep],
        robots=robots[keep].copy())
    logged.stats = {"steps": len(logged), "episodes": logged.episodes, "reached": int(term.sum()),
                    "truncated": int(trunc.sum()), "cut": int(cut.sum()), "dropped": int((~keep).sum()),
                    "success_rate": float(term.sum() / max(1, term.sum() + trunc.sum())),
                    "mean_reward": float(logged.rewards.mean()) if len(logged) else 0.0,
                    "wall_s": time.perf_counter() - t0}
    return logged


def log_transitions(ds: Dataset, cfg: OfflineConfig, normalizer: Normalizer | None = None):
    """The behaviour policy's transitions on ``ds`` as a d3rlpy ``MDPDataset`` (see :func:`roll_behaviour`)."""
    return roll_behaviour(ds, cfg, normalizer).to_mdp_dataset()


# -- 2. training ---------------------------------------------------------------------------------------------------
def make_algorithm(cfg: OfflineConfig):
    """The d3rlpy algorithm of ``cfg`` (created, not yet built: ``fit`` builds it from the data)."""
    d3rlpy = import_d3rlpy()
    check_algorithm(cfg.algorithm)
    common = {"batch_size": cfg.batch_size, "learning_rate": cfg.lr,
              "encoder_factory": d3rlpy.models.VectorEncoderFactory(hidden_units=list(cfg.hidden))}
    q_learning = {**common, "gamma": cfg.gamma, "target_update_interval": cfg.target_update_interval}
    algos = d3rlpy.algos
    config = {"cql": lambda: algos.DiscreteCQLConfig(**q_learning, alpha=cfg.cql_alpha),
              "bcq": lambda: algos.DiscreteBCQConfig(**q_learning, action_flexibility=cfg.bcq_flexibility,
                                                     beta=cfg.bc_beta),
              "bc": lambda: algos.DiscreteBCConfig(**common, beta=cfg.bc_beta),
              "dqn": lambda: algos.DQNConfig(**q_learning),
              "ddqn": lambda: algos.DoubleDQNConfig(**q_learning),
              "nfq": lambda: algos.NFQConfig(**common, gamma=cfg.gamma)}[cfg.algorithm]()
    return config.create(device=_device(cfg.device))


def _device(name: str) -> str:
    return name if ":" in name else ("cpu:0" if name == "cpu" else f"{name}:0")


def _epochs(n_steps: int, most: int = 10) -> int:
    """d3rlpy trains ``n_steps // n_steps_per_epoch`` whole epochs (nothing when n_steps < n_steps_per_epoch):
    the most epochs, up to ``most``, that divide ``n_steps`` exactly."""
    return max(k for k in range(1, most + 1) if n_steps % k == 0)


@dataclass
class OfflineResult:
    """What :func:`train_offline` returns."""

    model: Path
    out_dir: Path
    policy: OfflinePolicy
    #: logging statistics: steps, episodes, behaviour success rate, wall time, ...
    logged: dict[str, Any]
    n_steps: int
    train_s: float
    wall_s: float
    losses: list[dict[str, float]] = field(default_factory=list)
    #: evaluation rows (one per twin and shield setting) and their Markdown table
    rows: list[dict[str, Any]] = field(default_factory=list)
    markdown: str = ""


def train_offline(cfg: OfflineConfig, dataset: Dataset | Any | None = None) -> OfflineResult:
    """Log transitions, train ``cfg.algorithm`` on them with d3rlpy, save, and evaluate on ``cfg.eval_variants``.

    ``dataset``: the twin to log on (default: load ``cfg.dataset_name``), a stored logged dataset
    (:class:`~dtradar_data.store.transitions.LoggedDataset` or its name; also ``cfg.logged``), checked to have been
    logged on that twin with ``cfg.obs`` (:func:`dtradar_rl.offline.logged.check_compatible`), or an already logged d3rlpy
    ``MDPDataset``/``ReplayBuffer`` (then it must have been logged on ``cfg.dataset_name`` with ``cfg.obs``; its
    normaliser is refitted on that twin, which reproduces the one used for logging).
    """
    cfg = cfg.validate()
    d3rlpy = import_d3rlpy()
    t_start = time.perf_counter()
    torch.set_num_threads(cfg.threads or auto_threads())
    torch.set_flush_denormal(True)
    out = cfg.out_dir
    out.mkdir(parents=True, exist_ok=True)
    say = print if cfg.verbose else (lambda *a, **k: None)

    logged_data = dataset if isinstance(dataset, d3rlpy.dataset.ReplayBufferBase) else None
    ds = dataset if isinstance(dataset, Dataset) else load_dataset(cfg.dataset_name)
    normalizer = Normalizer.fit(ds)
    store_log = None
    if isinstance(dataset, (str, LoggedDataset)) or cfg.logged:
        store_log = as_logged(dataset if isinstance(dataset, (str, LoggedDataset)) else cfg.logged)
        check_compatible(store_log, cfg, ds)  # parent twin, its version, preset and normaliser
        logged_data = to_mdp_dataset(store_log)
    if logged_data is None:
        logged = roll_behaviour(ds, cfg, normalizer)
        stats = dict(logged.stats)
        say(f"logged {stats['steps']} steps, {stats['episodes']} episodes on {ds.name} with {cfg.behaviour} "
            f"(behaviour success {stats['success_rate']:.3f}) in {stats['wall_s']:.1f} s")
        logged_data = logged.to_mdp_dataset()
        if cfg.save_dataset:
            with open_atomic(out / "dataset.h5", "w+b") as f:
                logged_data.dump(f)
            logged.save_npz(out / "transitions.npz")
    elif store_log is not None:
        stats = {**store_log.meta["stats"], "source": f"{store_log.name}@{store_log.version}"}
    else:
        stats = {"steps": sum(ep.size() for ep in logged_data.episodes), "episodes": len(logged_data.episodes),
                 "source": "given"}
    obs_names = list(build_observations(ds, cfg.obs, normalizer).names)
    obs_dim = logged_data.episodes[0].observations.shape[-1]
    if obs_dim != len(obs_names):
        raise ConfigError(f"the logged observations have {obs_dim} features, the {cfg.obs!r} preset "
                          f"{len(obs_names)}", hint="pass the --obs preset the data was logged with")
    stats["transitions"] = int(logged_data.transition_count)

    d3rlpy.seed(cfg.seed)
    algo = make_algorithm(cfg)
    epochs = _epochs(cfg.n_steps)
    losses: list[dict[str, float]] = []
    t_fit = time.perf_counter()
    with quiet_d3rlpy():
        for epoch, metrics in algo.fitter(logged_data, n_steps=cfg.n_steps, n_steps_per_epoch=cfg.n_steps // epochs,
                                          experiment_name=cfg.algorithm, with_timestamp=False,
                                          logger_adapter=d3rlpy.logging.NoopAdapterFactory(),
                                          show_progress=False, save_interval=epochs + 1):
            row = {"epoch": epoch, "step": epoch * (cfg.n_steps // epochs),
                   **{k: float(v) for k, v in metrics.items() if not k.startswith("time_")}}
            losses.append(row)
            say(f"[{time.perf_counter() - t_start:6.1f}s] {cfg.algorithm} epoch {epoch}/{epochs} step {row['step']}  "
                + "  ".join(f"{k} {v:.4f}" for k, v in row.items() if k not in ("epoch", "step")))
    train_s = time.perf_counter() - t_fit

    model = out / "model.d3"
    tmp_model = out / ".model.d3.tmp"
    algo.save(str(tmp_model))
    os.replace(tmp_model, model)  # a kill mid-save leaves the previous model, never half of one
    meta = {"format": OFFLINE_FORMAT, "config": cfg.to_dict(), "normalizer": normalizer.to_dict(),
            "obs": {"preset": cfg.obs, "names": obs_names}, "dataset": {"name": ds.name, "version": ds.version},
            "stats": {"logged": stats, "n_steps": cfg.n_steps, "train_s": train_s}}
    write_atomic(out / "config.json", json.dumps(meta, indent=2) + "\n")
    _write_losses(losses, out / "losses.csv")

    policy = load_offline_policy(model, cfg.device)
    rows, md = [], ""
    if cfg.eval_variants:
        rows = evaluate_offline(policy, cfg, datasets={ds.name: ds})
        md = write_results(rows, out, meta)
    wall = time.perf_counter() - t_start
    return OfflineResult(model, out, policy, stats, cfg.n_steps, train_s, wall, losses, rows, md)


def _write_losses(losses: list[dict[str, float]], path: Path) -> None:
    keys = list(dict.fromkeys(k for row in losses for k in row))
    with open_atomic(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(losses)


# -- 3. evaluation -------------------------------------------------------------------------------------------------
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
    """A trained d3rlpy algorithm as a :class:`dtradar_rl.train.dqn.Policy`: greedy moves from ``algo.predict``, the same
    observation preset, normaliser and twin environment, and the same obstacle shield."""

    algo: Any = None
    algorithm: str = ""

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions (``algo.predict``); ``shield=True`` replaces a move into a neighbour sensed as occupied
        with the best allowed move by :class:`ActionScores` (via :meth:`Policy.act`)."""
        x = obs.detach().reshape(-1, obs.shape[-1]).cpu().numpy()
        a = torch.as_tensor(self.algo.predict(x), dtype=torch.long, device=obs.device).reshape(obs.shape[:-1])
        if shield:
            flags = obs[..., self.shield_columns()] > 0.5
            vetoed = ~flags.gather(-1, a[..., None]).squeeze(-1) & flags.any(-1)
            if bool(vetoed.any()):
                a[vetoed] = super().act(obs[vetoed], shield=True)
        return a


def load_offline_policy(path: str | Path, device: str = "cpu") -> OfflinePolicy:
    """Reload ``model.d3`` (or its directory) with the ``config.json`` written beside it."""
    path = Path(path)
    model = path / "model.d3" if path.is_dir() else path
    meta_path = model.parent / "config.json"
    if not model.exists() or not meta_path.exists():
        raise CheckpointError(f"no offline model at {model} (with config.json beside it)",
                              hint="train one first, e.g. `make offline SCENE=cubicle`")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError) as e:
        raise CheckpointError(f"{meta_path} cannot be read ({e})", hint="train again with `make offline`") from e
    if not isinstance(meta, dict) or meta.get("format") != OFFLINE_FORMAT:
        raise CheckpointError(f"{meta_path} is not a dtradar offline-RL config",
                              hint="pass the model.d3 written by `python -m dtradar_rl offline`")
    d3rlpy = import_d3rlpy()
    with quiet_d3rlpy():
        algo = d3rlpy.load_learnable(str(model), device=_device(device))
    cfg = OfflineConfig.from_dict(meta["config"])
    return OfflinePolicy(q=ActionScores(algo, cfg.algorithm), config=cfg,
                         normalizer=Normalizer.from_dict(meta["normalizer"]), obs_preset=meta["obs"]["preset"],
                         meta={"dataset": meta["dataset"], "stats": meta["stats"], "path": str(model)},
                         algo=algo, algorithm=cfg.algorithm)


def evaluate_offline(policy: OfflinePolicy, cfg: OfflineConfig,
                     datasets: dict[str, Dataset] | None = None) -> list[dict[str, Any]]:
    """Rows of :func:`dtradar_rl.evaluation.evaluate.evaluate` on every twin in ``cfg.eval_variants`` (missing ones are
    skipped), unshielded and, with ``cfg.shield`` and the neighbors preset, shielded."""
    rows = evaluate_twins(policy, cfg.scene, cfg.eval_variants, label=f"{cfg.algorithm}: ", pairs=cfg.pairs,
                          seed=cfg.eval_seed, max_steps=cfg.max_steps or None, device=cfg.device, shield=cfg.shield,
                          datasets=datasets)
    return [{**row, "algorithm": cfg.algorithm} for row, _, _ in rows]


__all__ = [
    "ALGORITHMS",
    "BEHAVIOURS",
    "ActionScores",
    "LoggedTransitions",
    "OfflineConfig",
    "OfflinePolicy",
    "OfflineResult",
    "ShortestPathOracle",
    "behaviour_actions",
    "check_algorithm",
    "evaluate_offline",
    "load_offline_policy",
    "log_transitions",
    "make_algorithm",
    "roll_behaviour",
    "train_offline",
]
