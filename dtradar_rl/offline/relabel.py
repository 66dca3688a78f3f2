"""Goal relabelling: any logged dataset seen as goal-conditioned data, with goals drawn from its own trajectories.

A logged step holds the robot's cell, its move and the target it was walking to. The observation is
``[cell_part[cell], target_part[target]]`` (:mod:`dtradar_rl.task.observations`) and the twin's table gives the rest
exactly (the next cell is ``next_cell[cell, action]``, the reward a function of the cells and the target), so the same
step can be replayed towards *another* goal: the target part of ``obs`` and ``next_obs`` is swapped for the goal's, the
reward and the terminal are recomputed for that goal. This is hindsight relabelling (Andrychowicz et al. 2017), the
field's answer for goal-conditioned offline data; OGBench (Park et al. 2024, arXiv 2410.20092) draws *actor* goals
from the future of the same trajectory (geometric) and *value* goals from a mix of the current, future and random
states.

Where a goal comes from (:class:`RelabelConfig`, probabilities summing to 1)
------------------------------------------------------------------------------
``own``     the logged target (no relabelling).
``future``  the cell the same episode reaches ``k`` steps later, ``k >= 1`` geometric with parameter
            ``1 - discount`` (mean ``1 / (1 - discount)`` steps), cut at the episode's last step (whose next cell is
            the target when the episode terminated). ``k = 1`` is this step's own next cell.
``random``  a cell drawn uniformly from the robot's connected component, the robot's own cell excepted.
``next``    this step's own next cell: a one-step success (OGBench's "current state" goal, shifted by one step to
            this MDP's convention that an episode ends on *arriving* at the target).

A drawn goal that is the robot's current cell (``next`` or ``future`` after a bump, a walk that came back) is **not
drawn**: it is replaced by the logged target. The MDP never decides on its own target (an episode ends on arriving,
and a reset never starts on the target), so such a step would be an absorbing state no evaluation visits. How often
it happens is counted (``fallback`` in the sampler's ``counts``, :mod:`dtradar_rl.offline.relabelled_sampler`, and in
a run's ``config.json``).

Rewards and terminals are exact: the terminal is ``next cell == goal``; the reward is the logged reward function
(``paper``, ``scaled``, ``euclidean`` or ``geodesic``, with the breadth-first distances of the twin for ``geodesic``)
computed with the float32 operations of the batched env that logged the data, so a relabelled step equals the step
the env gives from that cell with that action and that target, bit for bit, and ``own`` probability 1 reproduces the
logged table exactly. The ``Relabeller`` (:mod:`dtradar_rl.offline.relabeller`, the engine) checks this on every log
it opens (every row rebuilt with its logged target must equal the stored row), so a log that does not replay on its
twin is refused, not relabelled wrongly.

Relabelled steps have no episodes any more. d3rlpy sees them in one of two ways:

- training (:func:`dtradar_rl.offline.trainer.train_offline` with ``--relabel``): ``RelabelledSampler``
  (:mod:`dtradar_rl.offline.relabelled_sampler`), a d3rlpy ``ReplayBuffer`` over the logged episodes (its dataset
  info, observation shape and transition count are the log's) whose minibatches are relabelled transitions, built
  like the trainer's flat sampler (:func:`~dtradar_rl.offline.trainer.fast_sampling`: the same indices from numpy's
  global generator, the same arrays, terminal next observations zero), so every algorithm of
  :data:`~dtradar_rl.offline.config.ALGORITHMS` trains on it unchanged. ``resample="batch"`` draws fresh goals for
  every minibatch (OGBench's way; a few tens of microseconds per batch of 256), ``"run"`` one goal per logged step,
  fixed for the run.
- a plain d3rlpy dataset (``relabelled_mdp_dataset`` of :mod:`dtradar_rl.offline.relabeller`): one episode per
  relabelled step, a terminal step as a terminated one-row episode, any other as a two-row episode ending in a
  timeout (``obs``, then ``next_obs``), so ``transition_count`` equals the logged steps and no step bootstraps into
  another's goal.

Measured (``bench/bench_relabel.py``; expert, medium and mixed logs of the cubicle and Dallas Q3, seed 0, 4 000
updates): the imitation learners (bc, cql) train best on ``own-next`` (half the logged targets, half the next cell),
the Q-learners (bcq, dqn, ddqn, nfq) on ``ogbench``; ``--relabel auto`` picks that mix by algorithm
(:data:`AUTO_MIXES`). Goals from ``random`` alone, or future goals for the Q-learners without random ones, help little.

``--algorithm bc --relabel future`` is **GCBC** (goal-conditioned behaviour cloning, Ghosh et al. 2019; OGBench's
GCBC): DiscreteBC on the logged moves with goals from the future of the same trajectory.

Only static twins: a moving twin's observation depends on the snapshot, which the logged table does not keep.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_rl.task.config import Config, ConfigError

#: Where a goal can come from (the module docstring), in the order of :class:`RelabelConfig`'s probabilities.
SOURCES: tuple[str, ...] = ("own", "future", "random", "next")
OWN, FUTURE, RANDOM, NEXT = range(4)
#: The count of drawn goals that were the robot's current cell and became the logged target.
FALLBACK = 4
#: The columns of :attr:`~dtradar_rl.offline.relabeller.Relabeller._rows`.
ROW_CELL, ROW_ACTION, ROW_TARGET, ROW_NEXT, ROW_LAST, ROW_NEXT_ACTION, ROW_COLLIDES = range(7)
#: How often goals are drawn (:attr:`RelabelConfig.resample`).
RESAMPLE: tuple[str, ...] = ("batch", "run")

#: Named mixes (``--relabel <name>``); any other mix is written ``own=0.5,future=0.5``.
MIXES: dict[str, dict[str, float]] = {
    "none": {"own": 1.0},
    # GCBC's goals, OGBench's actor goals: the future of the same trajectory
    "future": {"future": 1.0},
    # half the logged targets, half the future of the trajectory
    "own-future": {"own": 0.5, "future": 0.5},
    # OGBench's value goals (p_curgoal 0.2, p_trajgoal 0.5, p_randomgoal 0.3)
    "ogbench": {"next": 0.2, "future": 0.5, "random": 0.3},
    # every goal the twin allows, drawn uniformly from the robot's component
    "random": {"random": 1.0},
    # half the logged targets, half the step's own next cell: the best measured for the imitation learners
    "own-next": {"own": 0.5, "next": 0.5},
}
#: ``--relabel auto``: the mix each algorithm trained best with on the expert and medium logs of the cubicle and Dallas
#: Q3 (seed 0, 4 000 updates, ``bench/bench_relabel.py``): the imitation learners (bc, and cql, whose conservative term
#: pulls towards the logged moves) on their targets and the next cell, the Q-learners on OGBench's value goals.
AUTO_MIXES: dict[str, str] = {
    "bc": "own-next",
    "cql": "own-next",
    "bcq": "ogbench",
    "dqn": "ogbench",
    "ddqn": "ogbench",
    "nfq": "ogbench",
}
AUTO = "auto"
MIX_FORM = (
    "a named mix ("
    + ", ".join(MIXES)
    + "), auto (the algorithm's best: "
    + ", ".join(f"{a} {m}" for a, m in AUTO_MIXES.items())
    + ") or probabilities like future=0.5,random=0.3,next=0.2"
)
#: Tolerance of "the probabilities sum to 1".
SUM_TOLERANCE = 1e-6
#: The default geometric parameter of ``future`` goals: mean offset 1 / (1 - 0.9) = 10 steps.
DEFAULT_DISCOUNT = 0.9


@dataclass(frozen=True)
class RelabelConfig(Config):
    """Where relabelled goals come from: four probabilities summing to 1, the future goals' discount, a seed."""

    own: float = 1.0
    """probability of the logged target (no relabelling)"""
    future: float = 0.0
    """probability of a cell the same episode reaches later: k >= 1 steps ahead, geometric with parameter
    1 - discount, cut at the episode's last step"""
    random: float = 0.0
    """probability of a cell drawn uniformly from the robot's connected component (its own cell excepted)"""
    next: float = 0.0
    """probability of this step's own next cell (a one-step success)"""
    discount: float = DEFAULT_DISCOUNT
    """future goals: the geometric offset's discount (mean offset 1 / (1 - discount) steps; 0 = the next cell)"""
    seed: int = 0
    """seed of the goal draws (a generator of its own: the minibatch indices stay d3rlpy's)"""
    resample: str = "batch"
    """batch: fresh goals for every minibatch; run: one goal per logged step, drawn once"""

    @property
    def probabilities(self) -> np.ndarray:
        return np.array([getattr(self, s) for s in SOURCES], np.float64)

    @property
    def is_identity(self) -> bool:
        """Every goal is the logged target: the logged transitions as they are."""
        return self.own == 1.0

    def check_ranges(self) -> None:
        # each one alone first: a sum with a NaN, an infinity or a negative part would name none of them
        mix = ",".join(f"{s}={getattr(self, s)!r}" for s in SOURCES)
        for s in SOURCES:
            v = getattr(self, s)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not (math.isfinite(v) and 0 <= v <= 1):
                raise ConfigError(
                    f"relabel probability {s!r} must be a finite number in [0, 1], got {v!r} (the mix: {mix})",
                    hint=f"give each of {', '.join(SOURCES)} a probability in [0, 1], together summing to 1, e.g. "
                    "--relabel future=0.5,random=0.3,next=0.2",
                )
        total = float(self.probabilities.sum())
        if abs(total - 1.0) > SUM_TOLERANCE:
            given = ", ".join(f"{s}={getattr(self, s):g}" for s in SOURCES if getattr(self, s))
            default_own = " (own is 1 unless given: set it to what the others leave)" if self.own == 1.0 else ""
            raise ConfigError(
                f"relabel probabilities must sum to 1, got {total:g} ({given or 'all 0'}){default_own}",
                hint="scale them to sum to 1 (a source not named is 0), e.g. --relabel future=0.5,random=0.3,next=0.2",
            )
        d = self.discount
        if isinstance(d, bool) or not isinstance(d, numbers.Real) or not (math.isfinite(d) and 0 <= d < 1):
            raise ConfigError(
                f"--relabel-discount must be in [0, 1), got {d!r}",
                hint="the future goals' offset is geometric with parameter 1 - discount; e.g. 0.9 (10 steps ahead "
                "on average)",
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral) or self.seed < 0:
            raise ConfigError(f"relabel seed must be an integer >= 0, got {self.seed!r}")
        if self.resample not in RESAMPLE:
            raise unknown_name("relabel resampling", self.resample, RESAMPLE)

    @classmethod
    def parse(cls, mix: str, algorithm: str | None = None, **kw: Any) -> RelabelConfig:
        """The config of ``mix``: a name of :data:`MIXES`, ``auto`` (:data:`AUTO_MIXES` of ``algorithm``) or
        ``source=p,...`` (sources not named are 0); ``kw`` sets ``discount``, ``seed`` and ``resample``."""
        text = str(mix).strip()
        if text == AUTO:
            if algorithm not in AUTO_MIXES:
                raise ConfigError(
                    f"--relabel auto picks the mix of the algorithm, got algorithm {algorithm!r}",
                    hint="one of " + ", ".join(AUTO_MIXES) + " (or name the mix)",
                )
            text = AUTO_MIXES[algorithm]
        if text in MIXES:
            probs = MIXES[text]
        elif "=" in text:
            probs = {}
            for part in text.split(","):
                name, sep, value = part.partition("=")
                name = name.strip()
                if not sep or not name:
                    raise ConfigError(f"--relabel {text!r}: {part!r} is not source=probability", hint=MIX_FORM)
                if name not in SOURCES:
                    raise unknown_name("relabel goal source", name, SOURCES)
                if name in probs:
                    raise ConfigError(f"--relabel {text!r} names {name!r} twice", hint=MIX_FORM)
                try:
                    probs[name] = float(value)
                except ValueError:
                    raise ConfigError(
                        f"--relabel {text!r}: the probability of {name!r} is {value.strip()!r}, not a number",
                        hint=MIX_FORM,
                    ) from None
        else:
            raise unknown_name("relabel mix", text, MIXES)
        return cls(**{s: float(probs.get(s, 0.0)) for s in SOURCES}, **kw)

    def describe(self) -> str:
        return ",".join(f"{s}={getattr(self, s):g}" for s in SOURCES if getattr(self, s))


#: The observation presets with a target part (the others cannot show a relabelled goal to the policy).
TARGET_PRESETS: tuple[str, ...] = ("goal", "neighbors")


def not_relabellable(ds: Dataset, preset: str) -> str | None:
    """Why a log of twin ``ds`` observed with ``preset`` cannot be relabelled (None when it can): a moving twin (its
    observations depend on the snapshot) or a preset without a target. ``--relabel auto`` then trains on the logged
    targets; a mix named explicitly is refused by :class:`~dtradar_rl.offline.relabeller.Relabeller` instead."""
    if ds.is_moving:
        return f"{ds.name} is a moving twin"
    if preset not in TARGET_PRESETS:
        return f"the {preset!r} observation has no target"
    return None


__all__ = [
    "AUTO_MIXES",
    "DEFAULT_DISCOUNT",
    "FALLBACK",
    "MIXES",
    "SOURCES",
    "TARGET_PRESETS",
    "RelabelConfig",
    "not_relabellable",
]
