"""Offline agents on honest logs: every logged step observed through the default agent's localisation filter.

An honest log (``log --sensing radio``) records what the robot's own sensors read: its own cell's radio under the
receiver's noise, the proximity sensor, its odometry and the target on the map (:mod:`dtradar_rl.task.sensing`). One
reading seldom tells the cell (fingerprints repeat, noise blurs them), so a memoryless learner on the raw readings
cannot localise. The robot's map can: the histogram filter of
:class:`~dtradar_rl.agents.radio_filter.RadioFilterAgent` turns the readings of an episode so far into a belief over
the map's cells (:meth:`~dtradar_rl.agents.radio_filter.RadioFilterAgent.belief_step`).

:class:`FilterSenses` replays every logged episode through that filter, step by step as a robot would run it, and
gives the learner a summary of the belief at each step (:data:`NAMES`): its mean position and spread, its largest
cell probability, the way to the target from the mean, the target, the proximity sensor and whether the last move
moved the robot; positions in units of half the map's extent about its centre. Nothing here reads the log's ``cell``
or ``target`` columns: the features follow from the recorded observations and the map (the scene's blueprint) alone.
:class:`FilteredPolicy` runs the same filter online and acts greedily with the learnt algorithm, never into a
neighbour its proximity sensor reports blocked (the filter agent's rule).

Goal relabelling is not built for these senses: the belief does not depend on the goal, so it could be, but the
relabeller rebuilds observations from cells, which an honest agent does not observe.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.agents.radio_filter import FilterConfig, RadioFilterAgent
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.offline.log_cache import LogCache, log_content
from dtradar_rl.task.sensing import ACTIONS, sensing_for
from dtradar_rl.task.twins import load_dataset

#: The learner's features of one step, in order.
NAMES: tuple[str, ...] = (
    "belief_x",
    "belief_y",
    "belief_spread",
    "belief_peak",
    "to_target_x",
    "to_target_y",
    "target_x",
    "target_y",
    *(f"blocked[{a}]" for a in ACTIONS),
    "moved",
)
#: Belief elements (episodes x cells) replayed together: the chunk of episodes is this over the map's cells.
CHUNK = 1 << 22


def map_agent(scene: str, sensing: str, noise: str, device: str = "cpu") -> RadioFilterAgent:
    """The filter of an honest offline agent: the scene's blueprint as the map, the log's sensing and noise model."""
    return RadioFilterAgent(load_dataset(f"{scene}/blueprint"), FilterConfig(scene, sensing, noise), device)


def belief_features(agent: RadioFilterAgent, belief: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
    """``float32[n, len(NAMES)]``: the learner's features of ``belief`` (``[n, cells]``) and the honest ``obs`` it
    was updated with."""
    pos = agent.positions
    center = (pos.max(0).values + pos.min(0).values) / 2
    scale = ((pos.max(0).values - pos.min(0).values).max() / 2).clamp(min=1e-6)
    mean = belief @ pos
    spread = (belief @ pos.square() - mean.square()).sum(1, keepdim=True).clamp(min=0).sqrt()
    peak = belief.max(1, keepdim=True).values
    target = obs[:, -2:]
    blocked, moved, _, _ = agent.readings(obs)
    parts = [(mean - center) / scale, spread / scale, peak, (target - mean) / scale, (target - center) / scale]
    return torch.cat([*parts, blocked.float(), moved.float()[:, None]], 1)


class FilterSenses:
    """The filter's features of every step of an honest log (module docstring), laid out as
    :class:`~dtradar_rl.offline.memory_senses.MemorySenses`' window: ``features[i]`` before step ``i``'s move,
    ``features[next_row[i]]`` after it (the next row inside an episode, an extra row after each episode's end)."""

    names = NAMES
    #: what the features follow from (set by :func:`filter_senses`): a d3rlpy dataset built with them is kept by it
    content: str = ""
    log: str = ""

    def __init__(self, logged: LoggedDataset, agent: RadioFilterAgent):
        t0 = time.perf_counter()
        a = logged.arrays()
        obs, next_obs = a["obs"], a["next_obs"]
        n = len(obs)
        ends = np.flatnonzero(a["terminated"] | a["truncated"])
        starts = np.r_[0, ends[:-1] + 1]
        self.features = np.zeros((n + len(ends), len(NAMES)), np.float32)
        self.next_row = np.arange(1, n + 1, dtype=np.int64)
        self.next_row[ends] = n + np.arange(len(ends))
        step = max(1, CHUNK // agent.mdp.num_cells)
        with torch.no_grad():
            for c in range(0, len(ends), step):
                self._replay(agent, obs, next_obs, starts[c : c + step], ends[c : c + step], n + c)
        self.build_s = time.perf_counter() - t0

    @property
    def dim(self) -> int:
        return len(NAMES)

    def _replay(self, agent, obs, next_obs, starts, ends, end_row) -> None:
        """Episodes ``starts..ends`` through the filter together, one step of all of them at a time."""
        t = lambda x: torch.as_tensor(x, dtype=torch.float32, device=agent.device)  # noqa: E731
        lengths = ends - starts + 1
        log_belief = agent.log_prior.expand(len(starts), -1).clone()
        for k in range(int(lengths.max())):
            e = np.flatnonzero(lengths > k)
            r = starts[e] + k
            o = t(obs[r])
            lb, belief = agent.belief_step(log_belief[e], o)
            log_belief[e] = lb
            self.features[r] = belief_features(agent, belief, o).cpu().numpy()
            last = r == ends[e]
            if last.any():  # the observation after the episode's last move
                o = t(next_obs[r[last]])
                _, belief = agent.belief_step(lb[last], o)
                self.features[end_row + e[last]] = belief_features(agent, belief, o).cpu().numpy()

    def arrays(self, a: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The log's arrays (:meth:`LoggedDataset.arrays`) with ``obs`` and ``next_obs`` replaced by the features."""
        n = len(a["action"])
        return {**a, "obs": self.features[:n], "next_obs": self.features[self.next_row]}


#: The features of the most recently opened logs in this process (the benchmark trains many agents on each), each
#: served only for the transitions and map it was built from (:mod:`dtradar_rl.offline.log_cache`).
_CACHE: LogCache[FilterSenses] = LogCache("filter features", 2)


def filter_senses(logged: LoggedDataset, scene: str, device: str = "cpu") -> FilterSenses:
    """The :class:`FilterSenses` of an honest log with its own sensing and noise model, kept for the next runs."""
    obs = logged.meta.get("observations") or {}
    sensing, noise = obs["sensing"], obs.get("noise", "none")
    blueprint = load_dataset(f"{scene}/blueprint")
    content = log_content(logged, f"filter {sensing} {noise} map {blueprint.name}@{blueprint.version}")

    def build() -> FilterSenses:
        agent = RadioFilterAgent(blueprint, FilterConfig(scene, sensing, noise), device)
        senses = FilterSenses(logged, agent)
        senses.content, senses.log = content, log_content(logged)
        return senses

    return _CACHE.get((str(logged.path), logged.name, logged.version), content, build, where=logged.name)


@dataclass
class FilteredPolicy:
    """A trained d3rlpy algorithm acting through the localisation filter on honest sensing: the part of
    :class:`~dtradar_rl.agents.policy.Policy` the evaluation uses (``env_for``, ``act``, ``obs_preset``, ``meta``)."""

    algo: Any
    scores: Any
    agent: RadioFilterAgent
    config: Any
    meta: dict[str, Any]
    obs_preset: str = "honest"

    def env_for(self, ds: Dataset, num_envs: int, *, noise=None, seed: int = 0, **kwargs) -> HonestNavEnv:
        """The honest env of ``ds`` with the run's sensing (a fresh belief per robot), under ``noise`` (default: the
        receiver noise the run's log was recorded with, which its filter assumes)."""
        self._log_belief = self.agent.log_prior.expand(num_envs, -1).clone()
        sensing, noise = sensing_for(self.config.sensing), noise or self.config.sensing_noise
        return HonestNavEnv.from_dataset(ds, num_envs, sensing=sensing, noise=noise, seed=seed, **kwargs)

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """The greedy move on the filter's features; a move the proximity sensor reports blocked is replaced by the
        best allowed one by the algorithm's action scores (``shield`` is accepted and ignored)."""
        obs = obs.to(self.agent.device)
        if getattr(self, "_log_belief", None) is None or self._log_belief.shape[0] != obs.shape[0]:
            self._log_belief = self.agent.log_prior.expand(obs.shape[0], -1).clone()
        with torch.no_grad():
            self._log_belief, belief = self.agent.belief_step(self._log_belief, obs)
            x = belief_features(self.agent, belief, obs)
        a = torch.as_tensor(self.algo.predict(x.numpy()), dtype=torch.long)
        blocked = self.agent.readings(obs)[0]
        vetoed = blocked.gather(1, a[:, None])[:, 0] & ~blocked.all(1)
        if bool(vetoed.any()):
            s = self.scores(x[vetoed]).masked_fill(blocked[vetoed], -torch.inf)
            a[vetoed] = s.argmax(1)
        return a


__all__ = ["NAMES", "FilterSenses", "FilteredPolicy", "belief_features", "filter_senses", "map_agent"]
