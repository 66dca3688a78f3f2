"""The offline benchmark's settings (:class:`OfflineBenchConfig`; the field docstrings are ``--help``) and the
names and budgets they default to. :mod:`dtradar_rl.experiments.offline_bench` runs it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from dtradar_data.core.ray_cluster import check_address_given
from dtradar_rl.evaluation.normalized import DEFAULT_SEED
from dtradar_rl.offline.behaviours import BEHAVIOURS, FAMILIES
from dtradar_rl.offline.config import ALGORITHMS, OfflineConfig, check_algorithm
from dtradar_rl.offline.ope import FQE_GAMMA
from dtradar_rl.offline.relabel import AUTO, RelabelConfig
from dtradar_rl.task.config import Config, ConfigError, check_unique
from dtradar_rl.task.sensing import sensing_for

NAMES = {
    "cql": "DiscreteCQL",
    "bcq": "DiscreteBCQ",
    "bc": "DiscreteBC",
    "dqn": "DQN",
    "ddqn": "DoubleDQN",
    "nfq": "NFQ",
}
#: The evaluation pairs' seed: the normalised score's (and ``make eval``'s).
EVAL_SEED = DEFAULT_SEED
#: Behaviours that act with a memoryless online DQN checkpoint.
NEED_ONLINE = ("epsilon-greedy", "mixture")
#: The default budget, chosen by measurement (cubicle 29 min, Dallas Q3 27 min on 2 cores before relabelling; Dallas Q3
#: 31.5 min relabelled, with the tables with senses, beside other jobs: docs/results/offline.md).
BENCH_UPDATES = 4_000
BENCH_FQE_STEPS = 1_000


@dataclass(frozen=True)
class OfflineBenchConfig(Config):
    """Offline-RL benchmark: d3rlpy algorithms on every logged dataset family of a scene, several seeds, scored on
    the normalised scale (0 random, 100 shortest-path expert) on the blueprint and dynamic twins, beside the
    behaviour itself and the online agent."""

    scene: str = "cubicle"
    """scene whose blueprint twin is logged on (synthetic-<nx>x<ny> for a stand-in without a ray tracer)"""
    behaviours: tuple[str, ...] = FAMILIES
    """datasets to train on: the families random, expert, medium, medium-replay, mixed (default: all five), or the
    older behaviours noisy-shortest, epsilon-greedy, mixture"""
    algorithms: tuple[str, ...] = ("cql", "bcq", "bc", "dqn", "ddqn", "nfq")
    """d3rlpy algorithms (cql, bcq, bc, dqn, ddqn, nfq)"""
    seeds: tuple[int, ...] = (0, 1, 2)
    """training seeds of every algorithm (the logged datasets are the same for all: seed 0)"""
    steps: int = 100_000
    """environment steps logged per dataset (not medium-replay: the medium agent's whole run)"""
    n_steps: int = BENCH_UPDATES
    """d3rlpy updates per run"""
    batch_size: int = 256
    """minibatch size of one update (0 = auto: 512 where the updates run in bf16, else 256; the samples a run draws
    are updates x batch: docs/results/offline.md)"""
    precision: str = "fp32"
    """arithmetic of the training updates: auto, fp32 or bf16 (OfflineConfig.precision; bf16 for bcq, dqn, ddqn and
    nfq only, bc and cql train in fp32)"""
    relabel: str = "auto"
    """goal relabelling of every run (dtradar_rl.offline.relabel): auto (each algorithm's best measured mix, the
    default), none (the logged targets, the benchmark before relabelling), or any mix --relabel takes"""
    senses: str = "auto"
    """what the deep learners observe (dtradar_rl.offline.memory_senses): auto (each algorithm's best measured: memory
    for bcq, dqn, ddqn, nfq, none for bc and cql), none (the logged, memoryless observation: the benchmark before
    senses) or memory (the online default agent's memory window, rebuilt from each log; evaluated in the memory env)"""
    sensing: str = "privileged"
    """what the logged datasets record and the agents observe: privileged (the neighbors preset: the robot's exact
    x, y and its neighbours' radio, the benchmark's upper bound) or an honest sensing (radio, rssi, no-radio... of
    dtradar_rl.task.sensing: the learners observe the localisation filter's belief, the online reference is the
    default radio-filter agent, the tabular learners' tables are followed through the filter, without a ceiling)"""
    sensing_noise: str = "realistic"
    """honest --sensing only: the receiver noise of the logged readings and of the evaluations"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the shortest-path move"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move"""
    checkpoint: str = ""
    """online agent evaluated beside the offline ones (default runs/<scene>/dqn/model.pt when it exists); the
    epsilon-greedy and mixture behaviours act with it (a memoryless one; else a tuned DQN is trained into
    <out>/online_dqn)"""
    online_steps: int = 600_000
    """environment steps of the online DQN when it has to be trained (tuned preset)"""
    num_envs: int = 256
    """robots logging in parallel"""
    pairs: int = 500
    """seeded (start, target) pairs per evaluated twin (500 = those of make eval and of the normalised score)"""
    variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins to evaluate on"""
    device: str = "cpu"
    """torch device of logging and training"""
    workers: int = 0
    """training processes side by side, one torch thread each (0 = auto: one per core when that many processes do
    proportionally more work right now, else 1; 1 = all in this process)"""
    executor: Literal["local", "ray"] = "local"
    """local (this machine's processes, see --workers) or ray (one Ray task of one CPU per training, as sweeps run;
    `pip install 'dtradar[ray]'`): the same table either way"""
    ray_address: str | None = None
    """--executor ray: an existing Ray cluster (e.g. auto or ray://head:10001) whose nodes hold the same data root;
    default: a local Ray on this machine's cores"""
    fqe: bool = True
    """estimate every agent's value with d3rlpy's FQE and measure it on the twin (--no-fqe: skip both)"""
    fqe_steps: int = BENCH_FQE_STEPS
    """FQE updates per agent (about 6 s each on 1 core at 1000)"""
    fqe_gamma: float = FQE_GAMMA
    """discount of the value FQE estimates and the rollouts measure (the agents train with 0.5, under which all
    reasonable agents are worth about the same; see dtradar_rl.offline.ope)"""
    deep: bool = True
    """train the d3rlpy algorithms (--no-deep: only the logged datasets' rows, the tabular learners and the ceilings,
    seconds per dataset)"""
    tabular: bool = True
    """also run the tabular batch learners (CE, VI-LCB, Π_b-SPIBB) and each dataset's ceiling (--no-tabular: skip;
    seconds per dataset, see dtradar_rl.tabular.batch)"""
    out: str = ""
    """output folder (default results/offline_bench/<scene>); one benchmark at a time writes it"""
    reuse: bool = True
    """reuse the runs an interrupted benchmark finished in --out (the same settings, logged data and library
    versions; each run's row is kept in its folder) and train only the rest (--no-reuse: train them all again)"""
    verbose: bool = True
    """print progress"""

    @property
    def honest(self) -> bool:
        return not sensing_for(self.sensing).privileged

    @property
    def out_dir(self) -> Path:
        """``--out``, by default results/offline_bench/<scene> (``<scene>-<sensing>`` with an honest sensing)."""
        return Path(self.out or f"results/offline_bench/{self.scene}" + (f"-{self.sensing}" if self.honest else ""))

    def check_ranges(self) -> None:
        super().check_ranges()
        # each value is one run (or one row, one column): a repeated one would be counted twice in every mean
        for name in ("seeds", "algorithms", "behaviours", "variants"):
            check_unique(getattr(self, name), name)
        # the mix is checked when the config is made, as OfflineConfig's is: a benchmark would otherwise log its
        # datasets and train the online agent before its first run refused it (an unknown algorithm: validate())
        for a in dict.fromkeys(self.algorithms):
            if a in ALGORITHMS or self.relabel.strip() != AUTO:
                RelabelConfig.parse(self.relabel, a)

    def validate(self) -> OfflineBenchConfig:
        for a in self.algorithms:
            check_algorithm(a)
        for b in self.behaviours:
            if b not in BEHAVIOURS:
                from dtradar_data.core.errors import unknown_name

                raise unknown_name("behaviour policy", b, BEHAVIOURS)
        if not self.seeds or not self.algorithms or not self.behaviours:
            raise ConfigError("--seeds, --algorithms and --behaviours must each list at least one value")
        for a in self.algorithms:
            OfflineConfig(algorithm=a, relabel=self.relabel).relabel_config()  # a mix that does not parse
        # an unknown --senses, --precision or --sensing (bcq: an algorithm that trains in either precision)
        OfflineConfig(
            algorithm="bcq",
            senses=self.senses,
            precision=self.precision,
            sensing=self.sensing,
            sensing_noise=self.sensing_noise,
            relabel="auto" if self.relabel.strip() == "auto" else self.relabel,
        ).validate()
        if self.workers < 0:
            raise ConfigError("--workers must be >= 0 (0 = one per CPU core)")
        check_address_given(self.ray_address, error=ConfigError)
        if self.executor != "ray" and self.ray_address:
            raise ConfigError("--ray-address applies to --executor ray only", hint="add --executor ray")
        if self.executor == "ray" and self.workers:
            raise ConfigError("--workers applies to --executor local only (Ray places one task per CPU)")
        if not 0 < self.fqe_gamma <= 1:
            raise ConfigError(f"--fqe-gamma must be in (0, 1], got {self.fqe_gamma}")
        if self.batch_size < 0:
            raise ConfigError("--batch-size must be >= 0 (0 = auto)")
        for name in ("steps", "n_steps", "pairs", "num_envs", "online_steps", "fqe_steps"):
            if getattr(self, name) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be >= 1")
        return self


__all__ = ["BENCH_FQE_STEPS", "BENCH_UPDATES", "EVAL_SEED", "NAMES", "NEED_ONLINE", "OfflineBenchConfig"]
