"""Behaviour policies that log offline-RL data, and the batched rollout that logs them.

Kinds (:data:`BEHAVIOURS`), all seeded, each acting for every robot of a
:class:`~dtradar_rl.envs.batched.BatchedNavEnv`:

- ``random``: a uniformly random move at every step.
- ``noisy-shortest``: with probability ``shortest_prob`` a breadth-first shortest-path move towards the target
  (ties broken at random; distances on the twin being logged), otherwise a random move.
- ``epsilon-greedy``: a trained DQN checkpoint (``model.pt`` of ``make train``): its greedy move, or with
  probability ``epsilon`` a random move. The checkpoint must observe with the logged preset.
- ``mixture``: the robots are split between the ``components`` (robot ``i`` uses component ``i mod k`` for the whole
  log), each one of the single kinds (those above, ``expert`` and ``medium``) with the same parameters. Which
  component acted is stored per step (column ``component``).

The **dataset families** (:data:`FAMILIES`), named like D4RL's (Fu et al. 2020) and needing no argument:

- ``random``: as above (normalised score about 0 by definition, see :mod:`dtradar_rl.evaluation.normalized`).
- ``expert``: ``noisy-shortest`` with probability :data:`EXPERT_SHORTEST_PROB` (0.95) of the shortest-path move: the
  normalised score's 100 is the noise-free expert, so this one scores a little below.
- ``medium``: an online DQN (the ``tuned`` preset, seeded) stopped at the first evaluation where the normalised
  score of this very behaviour reaches ``medium_target`` (50: half the expert), then logged with its greedy move
  replaced with probability :data:`MEDIUM_EPSILON` (0.1) by a random one. The agent is trained once per recipe and
  cached (:func:`dtradar_rl.offline.medium_agent.medium_agent`).
- ``medium-replay``: every transition that medium agent's run collected while it trained, up to its stop (its replay
  buffer; :func:`dtradar_rl.offline.collection.replay`).
- ``mixed``: a mixture of ``random``, ``medium`` and ``expert`` (robot ``i`` uses component ``i mod 3``). ``mixture``
  stays as the configurable mixture (``--components``, ``--checkpoint``); ``mixed`` is its family member.

And the OGBench-style families (:data:`OGBENCH_FAMILIES`, named by how they were collected): ``navigate`` (a noisy
expert walking from goal to goal), ``stitch`` (short hops) and ``explore`` (a persistent random walk), in
:mod:`dtradar_rl.offline.walks`.

The batched rollout that logs them is :func:`dtradar_rl.offline.collection.roll`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_data.core.files import sha256_file
from dtradar_rl.agents.policy import Policy
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.evaluation.normalized import DEFAULT_PAIRS, DEFAULT_SEED, METRIC, ShortestPathOracle
from dtradar_rl.offline import walks
from dtradar_rl.offline.checkpoint_twin import checkpoint_policy
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.noise import noise_model
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.sensing import sensing_for

#: The dataset families (D4RL's names), in the order ``--behaviour all`` logs them.
FAMILIES: tuple[str, ...] = ("random", "expert", "medium", "medium-replay", "mixed")
#: The OGBench-style families (:mod:`dtradar_rl.offline.walks`), logged by ``--behaviour all`` after D4RL's.
OGBENCH_FAMILIES: tuple[str, ...] = walks.KINDS
BEHAVIOURS: tuple[str, ...] = (
    "random",
    "noisy-shortest",
    "epsilon-greedy",
    "mixture",
    "expert",
    "medium",
    "medium-replay",
    "mixed",
    *OGBENCH_FAMILIES,
)
#: Kinds that act alone (a mixture's components).
SINGLE: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy", "expert", "medium")
#: ``--behaviour all``: every family of :data:`FAMILIES` and :data:`OGBENCH_FAMILIES` on the twin.
ALL = "all"

#: ``expert``: probability of the breadth-first shortest-path move (else a uniformly random one).
EXPERT_SHORTEST_PROB = 0.95
#: ``medium``: probability of a random move instead of the agent's greedy one, when logging and when scored.
MEDIUM_EPSILON = 0.1
#: ``medium``: the normalised score the agent's training stops at, and how far past it the stop may land before
#: the log says so (the agent is evaluated every :data:`MEDIUM_EVAL_EVERY` environment steps).
MEDIUM_TARGET = 50.0
MEDIUM_TOLERANCE = 10.0
MEDIUM_BUDGET = 200_000
MEDIUM_EVAL_EVERY = 2048
MEDIUM_PRESET = "tuned"
#: One torch thread: the same seed gives the same agent, bit for bit, whatever the load of the machine.
MEDIUM_THREADS = 1
MIXED_COMPONENTS: tuple[str, ...] = ("random", "medium", "expert")
GREEDY: tuple[str, ...] = ("epsilon-greedy", "medium")


@dataclass(frozen=True)
class BehaviourSpec:
    """A behaviour policy and all its parameters (they all enter a logged dataset's version)."""

    kind: str = "noisy-shortest"
    shortest_prob: float = 0.5
    epsilon: float = 0.3
    checkpoint: str = ""
    components: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy")
    medium_target: float = MEDIUM_TARGET
    medium_budget: int = MEDIUM_BUDGET
    hidden: tuple[int, ...] = (256, 256)
    #: the trained medium agent's model.pt, filled in by :func:`dtradar_rl.offline.medium_agent.resolve_spec` (not a
    #: parameter: the medium recipe is, see :meth:`medium_recipe`)
    medium_checkpoint: str = ""

    def validate(self) -> BehaviourSpec:
        if self.kind not in BEHAVIOURS:
            raise unknown_name("behaviour policy", self.kind, BEHAVIOURS)
        for c in self.components:
            if c not in SINGLE:
                raise unknown_name("mixture component", c, SINGLE)
        for name in ("shortest_prob", "epsilon"):
            v = getattr(self, name)
            if not 0 <= v <= 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be in [0, 1], got {v}")
        if self.kind == "mixture" and not self.components:
            raise ConfigError("--components must list at least one behaviour for a mixture")
        if all(g in self.used for g in GREEDY):
            raise ConfigError(
                "a mixture acts with one DQN: epsilon-greedy (--checkpoint) or medium (trained here), not both"
            )
        if self.needs_medium:
            if not 0 < self.medium_target <= 100:
                raise ConfigError(f"--medium-target must be in (0, 100], got {self.medium_target}")
            if self.medium_budget < 1:
                raise ConfigError(f"--medium-budget must be >= 1, got {self.medium_budget}")
        if "epsilon-greedy" in self.used and not self.checkpoint:
            raise ConfigError(
                f"the {self.kind} behaviour needs a trained DQN checkpoint",
                hint="pass --checkpoint runs/<scene>/dqn/model.pt (train one with `make train`)",
            )
        if "epsilon-greedy" in self.used and not Path(self.checkpoint).is_file():
            raise ConfigError(
                f"--checkpoint {self.checkpoint} does not exist",
                hint="train one with `make train SCENE=<scene>` or pass the model.pt it wrote",
            )
        return self

    @property
    def used(self) -> tuple[str, ...]:
        """The single kinds that act: the components of a mixture, else the kind itself (none for
        ``medium-replay``, which is a training run's replay buffer, not a policy)."""
        if self.kind == "mixture":
            return self.components
        if self.kind == "mixed":
            return MIXED_COMPONENTS
        return () if self.kind == "medium-replay" else (self.kind,)

    @property
    def needs_medium(self) -> bool:
        """Whether logging this behaviour needs the trained medium agent."""
        return "medium" in self.used or self.kind == "medium-replay"

    def medium_recipe(self) -> dict[str, Any]:
        """How the medium agent is made and when it stops: what, with the twin, the logging settings, the seed and
        the library versions, identifies it (its cache key, and part of the version of every dataset using it)."""
        return {
            "trainer": "dtradar_rl.train.dqn",
            "preset": MEDIUM_PRESET,
            "hidden": list(self.hidden),
            "budget": int(self.medium_budget),
            "threads": MEDIUM_THREADS,
            "target": float(self.medium_target),
            "score": f"normalized {METRIC} of the epsilon-greedy agent (epsilon {MEDIUM_EPSILON})",
            "epsilon": MEDIUM_EPSILON,
            "eval_every": MEDIUM_EVAL_EVERY,
            "pairs": DEFAULT_PAIRS,
            "eval_seed": DEFAULT_SEED,
            "stop": "the first evaluation at or above the target",
        }

    def to_dict(self) -> dict[str, Any]:
        """Only the parameters that matter for this kind (so unused settings never change a version); a
        checkpoint is recorded by its content hash, not its path; the medium agent by its recipe."""
        used = self.used
        d: dict[str, Any] = {"kind": self.kind}
        if self.kind in ("mixture", "mixed"):
            d["components"] = list(used)
            d["assignment"] = "robot i uses component i mod k"
        if "noisy-shortest" in used:
            d["shortest_prob"] = self.shortest_prob
        if "expert" in used:
            d["expert_shortest_prob"] = EXPERT_SHORTEST_PROB
        if "epsilon-greedy" in used:
            d["epsilon"] = self.epsilon
            d["checkpoint_sha256"] = sha256_file(Path(self.checkpoint))
        if self.needs_medium:
            d["medium"] = self.medium_recipe()
        if self.kind in OGBENCH_FAMILIES:
            d["walk"] = walks.parameters(self.kind)
        return d

    def describe(self) -> str:
        """One paragraph for the dataset card."""
        text = {
            "random": "a uniformly random move (X−, X+, Y−, Y+) at every step",
            "noisy-shortest": f"with probability {self.shortest_prob} a breadth-first shortest-path move towards the "
            "target (ties broken at random), otherwise a uniformly random move",
            "epsilon-greedy": f"the greedy move of a trained DQN checkpoint (sha256 recorded below), replaced with "
            f"probability {self.epsilon} by a uniformly random move",
            "expert": f"the D4RL expert level: with probability {EXPERT_SHORTEST_PROB} a breadth-first shortest-path "
            "move towards the target (ties broken at random), otherwise a uniformly random move",
            "medium": f"the D4RL medium level: the greedy move of an online DQN ({MEDIUM_PRESET} preset, this "
            f"log's seed) whose training stopped at the first evaluation (every {MEDIUM_EVAL_EVERY} environment "
            f"steps) where this behaviour's normalised score reached {self.medium_target:g}, replaced with "
            f"probability {MEDIUM_EPSILON} by a uniformly random move",
            **walks.DESCRIPTIONS,
        }
        if self.kind in ("mixture", "mixed"):
            parts = "; ".join(f"component {i} `{c}`: {text[c]}" for i, c in enumerate(self.used))
            return (
                f"A mixture{' (the `mixed` family)' if self.kind == 'mixed' else ''}: robot i acts with component "
                f"i mod {len(self.used)} for the whole log. {parts}."
            )
        if self.kind == "medium-replay":
            return (
                "`medium-replay` (the D4RL medium-replay level): every transition the `medium` agent's online DQN "
                f"({MEDIUM_PRESET} preset, this log's seed) collected while it trained, up to the stop where its "
                f"normalised score reached {self.medium_target:g}: its replay buffer in the order collected. The "
                "robots explored epsilon-greedily, epsilon decaying linearly from 1 over 40 % of a "
                f"{self.medium_budget}-step budget, so the data go from random moves to the medium agent's."
            )
        return f"`{self.kind}`: {text[self.kind]}."


@dataclass(frozen=True)
class BehaviourConfig(TwinConfig):
    """The twin and the behaviour policy that logs on it: the base of :class:`~dtradar_rl.offline.logged.LogConfig`
    and :class:`~dtradar_rl.offline.trainer.OfflineConfig`."""

    behaviour: str = "noisy-shortest"
    """behaviour policy: random, noisy-shortest, epsilon-greedy (a DQN checkpoint) or mixture (see --components); or a
    dataset family: D4RL's random, expert, medium, medium-replay, mixed, or OGBench's navigate, stitch, explore"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the breadth-first shortest-path move at each step"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move instead of the checkpoint's greedy one"""
    checkpoint: str = ""
    """epsilon-greedy (and mixtures using it): the DQN model.pt written by `make train`"""
    components: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy")
    """mixture: the behaviours robots are split between (robot i uses component i mod k)"""
    medium_target: float = MEDIUM_TARGET
    """medium, medium-replay, mixed: the normalised score (0 random, 100 shortest-path expert) at which the medium
    agent's training stops"""
    medium_budget: int = MEDIUM_BUDGET
    """medium, medium-replay, mixed: the medium agent's DQN budget in environment steps (its exploration decays over
    40 % of it); an agent that does not reach --medium-target within it is an error"""
    sensing: str = "privileged"
    """what a logged step records as the robot's observation: privileged (the --obs preset, which holds the robot's
    exact x, y and, with neighbors, the neighbouring cells' radio: an upper bound) or an honest sensing of
    dtradar_rl.task.sensing (radio, radio-no-proximity, no-angles, no-delay, no-gain, no-phase, rssi, no-radio: its
    own cell's radio under --sensing-noise, proximity, odometry and bumps, the target on the map); the behaviour acts
    the same either way"""
    sensing_noise: str = "realistic"
    """honest --sensing only: the receiver noise of the recorded readings (none, realistic, 2x)"""

    @property
    def honest(self) -> bool:
        """Whether the logged observations are an honest sensing's (else the privileged --obs preset's)."""
        return not sensing_for(self.sensing).privileged

    def spec(self) -> BehaviourSpec:
        return BehaviourSpec(
            self.behaviour,
            self.shortest_prob,
            self.epsilon,
            self.checkpoint,
            tuple(self.components),
            medium_target=self.medium_target,
            medium_budget=self.medium_budget,
            hidden=tuple(self.hidden),
        )

    def validate(self):
        super().validate()
        self.spec().validate()
        noise_model(self.sensing_noise)
        if self.honest and self.behaviour == "medium-replay":
            raise ConfigError(
                "medium-replay is the medium agent's replay buffer, which holds the privileged observations it "
                f"trained on, not what --sensing {self.sensing} reads",
                hint="log --behaviour medium with --sensing, or medium-replay with --sensing privileged",
            )
        return self


@dataclass
class Actor:
    """The behaviour's action for every robot given the current observations."""

    spec: BehaviourSpec
    env: BatchedNavEnv
    gen: torch.Generator
    policy: Policy | None = None
    oracle: ShortestPathOracle | None = None
    component: torch.Tensor = field(default=None)  # type: ignore[assignment]
    #: an OGBench-style family's walk (its moves' state, the episodes it starts), else None
    walk: walks.Walk | None = None

    def __post_init__(self):
        n = self.env.num_envs
        k = max(1, len(self.spec.used))
        self.component = torch.arange(n, device=self.env.device) % k
        if {"noisy-shortest", "expert", "navigate", "stitch"} & set(self.spec.used):
            self.oracle = ShortestPathOracle(self.env)
        if self.spec.kind in OGBENCH_FAMILIES:
            self.walk = walks.Walk(self.spec.kind, self.env, self.gen)

    def _single(self, kind: str, obs: torch.Tensor, random_actions: torch.Tensor, coin: torch.Tensor) -> torch.Tensor:
        if kind == "random":
            return random_actions
        if kind in ("noisy-shortest", "expert", "navigate", "stitch"):
            p = {"noisy-shortest": self.spec.shortest_prob, "expert": EXPERT_SHORTEST_PROB}.get(
                kind, walks.NAVIGATE_SHORTEST_PROB
            )
            # the oracle is refreshed when the pool grows (a walk's goals extend it)
            return torch.where(coin < p, self.oracle.act(self.gen), random_actions)
        if kind == "explore":
            return self.walk.explore(random_actions, coin)
        if kind not in GREEDY:
            raise ConfigError(f"the {kind} behaviour does not act: it is a training run's replay buffer")
        with torch.no_grad():
            greedy = self.policy.act(obs)
        eps = self.spec.epsilon if kind == "epsilon-greedy" else MEDIUM_EPSILON
        return torch.where(coin < eps, random_actions, greedy)

    def __call__(self, obs: torch.Tensor) -> torch.Tensor:
        n, dev = self.env.num_envs, self.env.device
        random_actions = torch.randint(4, (n,), generator=self.gen, device=dev)
        coin = torch.rand(n, generator=self.gen, device=dev)
        used = self.spec.used
        if len(used) == 1:
            return self._single(used[0], obs, random_actions, coin)
        out = random_actions.clone()
        for i, kind in enumerate(used):
            mask = self.component == i
            out = torch.where(mask, self._single(kind, obs, random_actions, coin), out)
        return out


@dataclass
class BehaviourPolicy(Policy):
    """A behaviour as a :class:`~dtradar_rl.agents.policy.Policy`, so :func:`dtradar_rl.evaluation.evaluate.rollout`
    measures it on any twin like a trained agent: the env it asks for gets an :class:`Actor` (its shortest-path oracle
    plans on the twin being evaluated; robot ``i`` of a mixture uses component ``i mod k``). Stochastic, seeded by
    ``seed``."""

    spec: BehaviourSpec = field(default_factory=BehaviourSpec)
    seed: int = 0
    greedy: Policy | None = None
    _actor: Actor | None = None

    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        env = BatchedNavEnv.from_dataset(ds, num_envs, obs=self.obs_preset, normalizer=self.normalizer, **kwargs)
        gen = torch.Generator(device=env.device)
        gen.manual_seed(self.seed)
        self._actor = Actor(self.spec, env, gen, policy=self.greedy)
        return env

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        if self._actor is None:
            raise ConfigError(
                "a behaviour policy acts only in the env it made (use dtradar_rl.evaluation.evaluate.rollout)"
            )
        return self._actor(obs)


def behaviour_policy(
    spec: BehaviourSpec, ds: Dataset, obs: str = "neighbors", seed: int = 0, device: str = "cpu"
) -> BehaviourPolicy:
    """The behaviour ``spec`` observing like a log on ``ds`` (its preset, the normaliser fitted on ``ds``); a
    ``medium`` or ``mixed`` spec resolved first (:func:`dtradar_rl.offline.medium_agent.resolve_spec`)."""
    spec.validate()
    if not spec.used:
        raise ConfigError(
            f"the {spec.kind} dataset is a training run's replay buffer, not a policy that can act",
            hint="roll out the medium behaviour instead (its agent at the stop)",
        )
    normalizer = Normalizer.fit(ds)
    return BehaviourPolicy(
        q=None,
        config=None,
        normalizer=normalizer,
        obs_preset=obs,
        meta={"dataset": {"name": ds.name, "version": ds.version}},
        spec=spec,
        seed=seed,
        greedy=checkpoint_policy(spec, obs, normalizer, device, ds=ds),
    )


__all__ = [
    "ALL",
    "BEHAVIOURS",
    "EXPERT_SHORTEST_PROB",
    "FAMILIES",
    "MEDIUM_EPSILON",
    "OGBENCH_FAMILIES",
    "MEDIUM_TARGET",
    "MEDIUM_TOLERANCE",
    "MIXED_COMPONENTS",
    "Actor",
    "BehaviourConfig",
    "BehaviourPolicy",
    "BehaviourSpec",
    "ShortestPathOracle",
    "behaviour_policy",
    "checkpoint_policy",
]
