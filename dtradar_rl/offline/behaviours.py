"""Behaviour policies that log offline-RL data, and the batched rollout that logs them.

Kinds (:data:`BEHAVIOURS`), all seeded, each acting for every robot of a
:class:`~dtradar_rl.envs.batched.BatchedNavEnv`:

- ``random``: a uniformly random move at every step.
- ``noisy-shortest``: with probability ``shortest_prob`` a breadth-first shortest-path move towards the target
  (ties broken at random; distances on the twin being logged), otherwise a random move.
- ``epsilon-greedy``: a trained DQN checkpoint (``model.pt`` of ``make train``): its greedy move, or with
  probability ``epsilon`` a random move. The checkpoint must observe with the logged preset.
- ``mixture`` (the D4RL "medium-replay" idea: data of several qualities in one set): the robots are split between
  the ``components`` (robot ``i`` uses component ``i mod k`` for the whole log), each one of the kinds above with
  the same parameters. Which component acted is stored per step (column ``component``).

The batched rollout that logs them is :func:`dtradar_rl.offline.collection.roll`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_data.core.files import sha256_file
from dtradar_rl.agents.policy import Policy
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.task.config import ConfigError, TwinConfig
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.train.checkpoints import load_policy

BEHAVIOURS: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy", "mixture")
SINGLE: tuple[str, ...] = BEHAVIOURS[:3]


@dataclass(frozen=True)
class BehaviourSpec:
    """A behaviour policy and all its parameters (they all enter a logged dataset's version)."""

    kind: str = "noisy-shortest"
    shortest_prob: float = 0.5
    epsilon: float = 0.3
    checkpoint: str = ""
    components: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy")

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
        """The single kinds that act: the components of a mixture, else the kind itself."""
        return self.components if self.kind == "mixture" else (self.kind,)

    def to_dict(self) -> dict[str, Any]:
        """Only the parameters that matter for this kind (so unused settings never change a version); a
        checkpoint is recorded by its content hash, not its path."""
        used = self.used
        d: dict[str, Any] = {"kind": self.kind}
        if self.kind == "mixture":
            d["components"] = list(self.components)
            d["assignment"] = "robot i uses component i mod k"
        if "noisy-shortest" in used:
            d["shortest_prob"] = self.shortest_prob
        if "epsilon-greedy" in used:
            d["epsilon"] = self.epsilon
            d["checkpoint_sha256"] = sha256_file(Path(self.checkpoint))
        return d

    def describe(self) -> str:
        """One paragraph for the dataset card."""
        text = {
            "random": "a uniformly random move (X−, X+, Y−, Y+) at every step",
            "noisy-shortest": f"with probability {self.shortest_prob} a breadth-first shortest-path move towards the "
            "target (ties broken at random), otherwise a uniformly random move",
            "epsilon-greedy": f"the greedy move of a trained DQN checkpoint (sha256 recorded below), replaced with "
            f"probability {self.epsilon} by a uniformly random move",
        }
        if self.kind == "mixture":
            parts = "; ".join(f"component {i} `{c}`: {text[c]}" for i, c in enumerate(self.components))
            return (
                f"A mixture (the D4RL medium-replay idea): robot i acts with component i mod "
                f"{len(self.components)} for the whole log. {parts}."
            )
        return f"`{self.kind}`: {text[self.kind]}."


@dataclass(frozen=True)
class BehaviourConfig(TwinConfig):
    """The twin and the behaviour policy that logs on it: the base of :class:`~dtradar_rl.offline.logged.LogConfig`
    and :class:`~dtradar_rl.offline.trainer.OfflineConfig`."""

    behaviour: str = "noisy-shortest"
    """behaviour policy: random, noisy-shortest, epsilon-greedy (a DQN checkpoint) or mixture (see --components)"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the breadth-first shortest-path move at each step"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move instead of the checkpoint's greedy one"""
    checkpoint: str = ""
    """epsilon-greedy (and mixtures using it): the DQN model.pt written by `make train`"""
    components: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy")
    """mixture: the behaviours robots are split between (robot i uses component i mod k)"""

    def spec(self) -> BehaviourSpec:
        return BehaviourSpec(self.behaviour, self.shortest_prob, self.epsilon, self.checkpoint, tuple(self.components))

    def validate(self):
        super().validate()
        self.spec().validate()
        return self


class ShortestPathOracle:
    """Breadth-first shortest-path moves for every robot of a :class:`BatchedNavEnv` (the behaviour's expert)."""

    def __init__(self, env: BatchedNavEnv):
        self.env = env
        self._pool_size = -1
        self._refresh()

    def _refresh(self) -> None:
        env = self.env
        if env.pool.numel() != self._pool_size:  # targets are rows of env.pool; it only grows
            if env.dist.shape[1]:  # the geodesic reward already keeps this table
                self.dist = env.dist
            else:
                d = env.mdp.bfs_distances_many(env.pool.cpu().numpy())
                self.dist = torch.as_tensor(d, dtype=torch.int32, device=env.device)
            self._pool_size = env.pool.numel()

    def optimal(self) -> torch.Tensor:
        """``bool[num_envs, 4]``: moves that shorten the breadth-first distance to the target by one."""
        self._refresh()
        env = self.env
        d_now = self.dist[env.tpool, env.cell]
        d_next = self.dist[env.tpool[:, None], env.next_cell[env.cell]]
        return d_next == (d_now - 1)[:, None]  # a collision stays in place, so it is never optimal

    def act(self, gen: torch.Generator) -> torch.Tensor:
        """One shortest-path move per robot, ties broken at random."""
        good = self.optimal()
        u = torch.rand(good.shape, generator=gen, device=good.device) + good.float()
        return u.argmax(1)


@dataclass
class Actor:
    """The behaviour's action for every robot given the current observations."""

    spec: BehaviourSpec
    env: BatchedNavEnv
    gen: torch.Generator
    policy: Policy | None = None
    oracle: ShortestPathOracle | None = None
    component: torch.Tensor = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        n = self.env.num_envs
        k = len(self.spec.used)
        self.component = torch.arange(n, device=self.env.device) % k
        if "noisy-shortest" in self.spec.used:
            self.oracle = ShortestPathOracle(self.env)

    def _single(self, kind: str, obs: torch.Tensor, random_actions: torch.Tensor, coin: torch.Tensor) -> torch.Tensor:
        if kind == "random":
            return random_actions
        if kind == "noisy-shortest":
            return torch.where(coin < self.spec.shortest_prob, self.oracle.act(self.gen), random_actions)
        with torch.no_grad():
            greedy = self.policy.act(obs)
        return torch.where(coin < self.spec.epsilon, random_actions, greedy)

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


def checkpoint_policy(spec: BehaviourSpec, obs: str, normalizer: Normalizer, device: str = "cpu") -> Policy | None:
    """The DQN of an ``epsilon-greedy`` behaviour, checked to observe like the log (preset and normaliser)."""
    if "epsilon-greedy" not in spec.used:
        return None
    policy = load_policy(spec.checkpoint, device)
    if getattr(policy.config, "memory_radius", 0):
        raise ConfigError(
            f"the checkpoint {spec.checkpoint} is a memory agent ({policy.config.preset} preset): a logged step holds "
            "the twin's observation only, not the agent's memory of the episode",
            hint='log with a memoryless agent: make train SCENE=<scene> ARGS="--preset tuned --out runs/<scene>/tuned"',
        )
    if policy.obs_preset != obs:
        raise ConfigError(
            f"the checkpoint {spec.checkpoint} observes {policy.obs_preset!r}, the log {obs!r}",
            hint=f"pass --obs {policy.obs_preset}",
        )
    if not np.allclose(policy.normalizer.mean, normalizer.mean, rtol=1e-5, atol=1e-6) or not np.allclose(
        policy.normalizer.std, normalizer.std, rtol=1e-5, atol=1e-6
    ):
        raise ConfigError(
            f"the checkpoint {spec.checkpoint} was trained on another twin (its feature normaliser "
            "differs from the logged twin's)",
            hint="log on the twin the checkpoint was trained on",
        )
    return policy


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
    """The behaviour ``spec`` observing like a log on ``ds`` (its preset, the normaliser fitted on ``ds``)."""
    spec.validate()
    normalizer = Normalizer.fit(ds)
    return BehaviourPolicy(
        q=None,
        config=None,
        normalizer=normalizer,
        obs_preset=obs,
        meta={"dataset": {"name": ds.name, "version": ds.version}},
        spec=spec,
        seed=seed,
        greedy=checkpoint_policy(spec, obs, normalizer, device),
    )


__all__ = [
    "BEHAVIOURS",
    "Actor",
    "BehaviourConfig",
    "BehaviourPolicy",
    "BehaviourSpec",
    "ShortestPathOracle",
    "behaviour_policy",
    "checkpoint_policy",
]
