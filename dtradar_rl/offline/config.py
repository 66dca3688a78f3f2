"""The offline baselines' settings: which d3rlpy algorithm, on which logged data, with which hyper-parameters.

:class:`OfflineConfig` extends :class:`~dtradar_rl.offline.behaviours.BehaviourConfig` (the twin, and the behaviour
that logs on it when no stored ``--logged`` dataset is named).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from dtradar_data.core.errors import unknown_name
from dtradar_rl.offline.behaviours import BehaviourConfig
from dtradar_rl.offline.precision import AUTO_BATCH, BF16_ALGORITHMS, PRECISIONS, resolve_precision
from dtradar_rl.offline.relabel import DEFAULT_DISCOUNT, RelabelConfig
from dtradar_rl.task.config import DEFAULT_IN_HELP, ConfigError
from dtradar_rl.task.runs import run_dir

OFFLINE_FORMAT = "dtradar-offline/1"
#: Algorithm names and the d3rlpy config class each one uses.
ALGORITHMS: dict[str, str] = {
    "cql": "DiscreteCQLConfig",
    "bcq": "DiscreteBCQConfig",
    "bc": "DiscreteBCConfig",
    "dqn": "DQNConfig",
    "ddqn": "DoubleDQNConfig",
    "nfq": "NFQConfig",
}


#: The senses an offline agent can train with: ``none`` (what the log holds: the memoryless observation),
#: ``memory`` (the default online agent's memory window, rebuilt from the log: dtradar_rl.offline.memory_senses) or,
#: on an honest log (``--sensing``), ``filter`` (the localisation filter's belief: dtradar_rl.offline.filter_senses).
SENSES = ("auto", "none", "memory", "filter")

#: ``--senses auto``: each algorithm's best measured (Dallas Q3 expert and medium, 4 000 updates, relabelled; the
#: cubicle within a few points either way: docs/results/offline.md). The imitation-anchored learners (bc; cql, whose
#: conservative term pulls towards the logged moves) read the logged trail behind them as the next move's cue and fall
#: to 15-42 with the memory window, the Q-learners gain 5-24 points with it.
AUTO_SENSES: dict[str, str] = {
    "bc": "none",
    "cql": "none",
    "bcq": "memory",
    "dqn": "memory",
    "ddqn": "memory",
    "nfq": "memory",
}
#: The memory window of ``--senses memory``: the default online preset's (``DQNConfig()``), checked by a test.
MEMORY_SETTINGS = {"memory_radius": 5, "memory_bumps": False, "memory_visits": True, "escape_after": 2}

#: torch threads of one d3rlpy training by default (see :attr:`OfflineConfig.threads`)
TRAIN_THREADS = 1


@dataclass(frozen=True)
class OfflineConfig(BehaviourConfig):
    """Offline RL with d3rlpy: log a behaviour policy on a twin, train on the log, evaluate on the twins."""

    threads: int = TRAIN_THREADS
    """torch CPU threads of training (0 = auto, as for the online trainer: up to 2, fewer on a busy machine). Default 1:
    d3rlpy's small networks ran 6-40x slower with two threads whenever another process held a core, and the weights
    are the same with 1 or 2 (bench/bench_offline_speed.py)"""
    algorithm: str = "bcq"
    """d3rlpy algorithm: cql (DiscreteCQL), bcq (DiscreteBCQ), bc (DiscreteBC), dqn (DQN, offline), ddqn
    (DoubleDQN, offline), nfq (NFQ: fitted Q, no target network). Default bcq, the best measured: with the default
    senses and relabelling (memory, ogbench) it is the best deep learner of random, expert and mixed data on Dallas Q3
    and the cubicle (3 seeds; Dallas Q3 expert 76.4 blueprint / 71.9 dynamic against cql's 68.9 / 56.3, the default
    before; DoubleDQN leads on medium, NFQ on medium-replay: docs/results/offline.md)"""
    reward: str = "geodesic"
    """reward logged with each transition: paper, scaled, euclidean or geodesic (see dtradar_rl.task.rewards)"""
    transitions: int = 100_000
    """environment steps to log when no --logged dataset is given (all robots together; rounded up to whole steps of
    num-envs robots): the log is the stored dataset <scene>/<variant>/<behaviour>, reused when one with the same
    inputs exists"""
    n_steps: int = 10_000
    """d3rlpy gradient updates"""
    batch_size: int = 256
    """minibatch size of one update (0 = auto: 512 where the updates run in bf16, else 256)"""
    lr: float = 1e-3
    """Adam learning rate (d3rlpy's Atari default, 6.25e-5, is too slow for a short run; 1e-3 beat 3e-4 for every
    algorithm measured on the cubicle's expert and medium data at 3 K updates, by 10-50 points of normalised score,
    and for DQN at 10 K too; 3e-3 was no better: docs/results/offline-first-benchmark.md)"""
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
    """twins of the scene to evaluate on after training (empty = no evaluation); a run on a moving twin's log is
    evaluated on the moving twin too"""
    pairs: int = 500
    """seeded (start, target) pairs per evaluated twin"""
    eval_seed: int = 2024
    """seed of the evaluation pairs (the same as `make eval`)"""
    shield: bool = True
    """also report the policy with the obstacle shield (neighbors preset only)"""
    latency: bool = True
    """time one greedy decision on every evaluated twin (the results' latency columns; the offline benchmark, which
    does not report them, skips it: ~0.5 s per twin)"""
    logged: Annotated[str, DEFAULT_IN_HELP] = ""
    """train on this stored logged dataset (e.g. cubicle/blueprint/mixture@v0, see `dtradar_rl log`); default: log
    (or reuse) <scene>/<variant>/<behaviour> with --behaviour, --transitions and --seed"""
    relabel: str = "auto"
    """goal relabelling of the logged steps (dtradar_rl.offline.relabel; rewards and terminals recomputed exactly for
    each goal): auto, the default (the algorithm's best measured mix: own-next for bc and cql, ogbench for bcq, dqn,
    ddqn, nfq); none (the logged targets: every run before relabelling existed); future (goals from the future of the
    same episode: with --algorithm bc this is GCBC); own-future; own-next (own 0.5, next 0.5); ogbench (OGBench's
    value goals: next 0.2, future 0.5, random 0.3); random; or probabilities like own=0.5,future=0.3,random=0.2
    (sources own, future, random, next; summing to 1)"""
    relabel_discount: float = DEFAULT_DISCOUNT
    """relabelling: future goals are k >= 1 steps ahead, k geometric with parameter 1 - discount (mean 1 / (1 -
    discount) steps), cut at the episode's end"""
    relabel_resample: str = "batch"
    """relabelling: batch (fresh goals for every minibatch, as OGBench) or run (one goal per logged step, drawn once
    with --seed)"""
    senses: str = "auto"
    """what the agent observes of each logged step: auto (the algorithm's best measured: memory for bcq, dqn, ddqn,
    nfq; none for bc and cql), none (the logged observation, memoryless: every run before senses existed) or memory
    (the online default agent's senses: the logged observation followed by the memory window of what it sensed and
    visited this episode and its earlier stands on its cell, rebuilt exactly from the log; evaluated in the same memory
    env, with its loop escape: dtradar_rl.offline.memory_senses); with an honest --sensing, filter (the only one, and
    what auto picks: the default agent's localisation filter replayed along each logged episode, its belief summarised
    as the learner's input: dtradar_rl.offline.filter_senses)"""
    precision: str = "fp32"
    """arithmetic of the training updates: fp32 (the default), bf16 (each update under torch.autocast in bfloat16;
    weights, optimiser and evaluation in fp32; bcq, dqn, ddqn and nfq only; needs a CPU with bf16 matrix units, AMX or
    AVX512-BF16, else it is slower), or auto (bf16 for those four where the CPU has the units, else fp32). On a 2-core
    Xeon with AMX, Dallas Q3 expert BCQ in bf16 at batch 512 trained in about fp32's time at 256 to 82.0 against 75.3;
    the full offline benchmark with auto gained 3.8-8.2 per family but took 35.2 min against its 30, so fp32 stays the
    default (docs/results/offline.md)"""
    out: Annotated[str, DEFAULT_IN_HELP] = ""
    """output directory (default: runs/<scene>/offline/<algorithm>)"""

    @classmethod
    def from_dict(cls, d):
        """The config saved by ``to_dict``; a config saved before a field existed keeps the default it had then
        (:data:`SAVED_DEFAULTS`: no relabelling), so an old run's ``config.json`` keeps its meaning."""
        return super().from_dict({**SAVED_DEFAULTS, **d})

    def relabel_config(self) -> RelabelConfig:
        """The goal relabelling of this run (seeded with ``seed``): :class:`~dtradar_rl.offline.relabel.RelabelConfig`
        of ``relabel``, ``relabel_discount`` and ``relabel_resample``."""
        return RelabelConfig.parse(
            self.relabel,
            self.algorithm,
            discount=self.relabel_discount,
            seed=self.seed,
            resample=self.relabel_resample,
        )

    @property
    def resolved_senses(self) -> str:
        """``senses`` with ``auto`` resolved for ``algorithm`` (:data:`AUTO_SENSES`; memoryless for another preset
        than ``neighbors``, whose flags the memory reads): ``none`` or ``memory``."""
        if self.senses != "auto":
            return self.senses
        if self.honest:  # honest readings localise only through the filter over the map
            return "filter"
        return AUTO_SENSES.get(self.algorithm, "none") if self.obs == "neighbors" else "none"

    # The memory env's settings (read by Policy.env_for and the loop escape): the default online preset's with
    # memory senses, none without.
    def _memory(self, key: str, off):
        return MEMORY_SETTINGS[key] if self.resolved_senses == "memory" else off

    @property
    def memory_radius(self) -> int:
        return self._memory("memory_radius", 0)

    @property
    def memory_bumps(self) -> bool:
        return self._memory("memory_bumps", False)

    @property
    def memory_visits(self) -> bool:
        return self._memory("memory_visits", False)

    @property
    def escape_after(self) -> int:
        return self._memory("escape_after", 0)

    @property
    def update_precision(self) -> str:
        """``precision`` with ``auto`` resolved for this algorithm, device and CPU (:func:`resolve_precision`)."""
        return resolve_precision(self.precision, self.algorithm, self.device)

    @property
    def update_batch_size(self) -> int:
        """``batch_size`` with 0 resolved for :attr:`update_precision` (:data:`AUTO_BATCH`)."""
        return self.batch_size or AUTO_BATCH[self.update_precision]

    @property
    def out_dir(self) -> Path:
        return Path(self.out or run_dir(self.scene, "offline", self.algorithm))

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(1, "transitions", "n_steps", "target_update_interval", "pairs")
        self.check_at_least(0, "batch_size")
        self.check_at_least(0, "eval_seed")
        self.check_within(0, 1, "gamma", "bcq_flexibility", open_interval=True)
        if not self.lr > 0:
            raise ConfigError(f"--lr must be > 0, got {self.lr}", hint="e.g. --lr 1e-3")
        self.check_at_least(0, "bc_beta", "cql_alpha")
        if self.algorithm in ALGORITHMS or self.relabel.strip() != "auto":  # (validate names a wrong algorithm)
            self.relabel_config()  # a mix that does not parse, or probabilities that are not a distribution

    def validate(self) -> OfflineConfig:
        super().validate()
        check_algorithm(self.algorithm)
        if self.senses not in SENSES:
            raise unknown_name("senses", self.senses, SENSES)
        if self.precision not in PRECISIONS:
            raise unknown_name("precision", self.precision, PRECISIONS)
        if self.precision == "bf16" and self.algorithm not in BF16_ALGORITHMS:
            raise ConfigError(
                f"--precision bf16 does not train --algorithm {self.algorithm} (d3rlpy's loss logging needs fp32)",
                hint=f"use --precision fp32, or one of {', '.join(BF16_ALGORITHMS)}",
            )
        if self.honest and self.senses not in ("auto", "filter"):
            raise ConfigError(
                f"--sensing {self.sensing}: an honest agent senses through the localisation filter, not --senses "
                f"{self.senses} (which extends the privileged observation)",
                hint="drop --senses (auto is filter) or pass --senses filter",
            )
        if self.senses == "filter" and not self.honest:
            raise ConfigError(
                "--senses filter localises from honest readings, and --sensing privileged records the position",
                hint="pass --sensing radio (and train on a log made with it)",
            )
        if self.honest and self.relabel.strip() not in ("auto", "none"):
            raise ConfigError(
                f"--relabel {self.relabel}: goal relabelling is not built for honest logs (the relabeller rebuilds "
                "observations from cells, which an honest agent does not observe)",
                hint="drop --relabel (auto trains on the logged targets) or pass --relabel none",
            )
        if self.senses == "memory" and self.obs != "neighbors":  # (auto: memoryless where the log has no flags)
            raise ConfigError(
                f"--senses memory senses obstacles through the 'neighbors' observation, got --obs {self.obs}",
                hint="use --obs neighbors (the default) or --senses none",
            )
        return self


#: What a config saved without a field meant by it (:meth:`OfflineConfig.from_dict`): relabelling, senses and the
#: precision came later.
SAVED_DEFAULTS: dict[str, object] = {"relabel": "none", "senses": "none", "precision": "fp32"}


def check_algorithm(name: str) -> str:
    """Return ``name`` if it is a known offline algorithm, else raise :class:`UnknownNameError` with a suggestion."""
    if name not in ALGORITHMS:
        raise unknown_name("offline algorithm", name, ALGORITHMS)
    return name
