"""The normalised score of a navigation policy on a twin, defined once: 0 = uniform random, 100 = the breadth-first
shortest-path expert (the D4RL convention, Fu et al. 2020: ``100 · (score − random) / (expert − random)``).

    from dtradar_rl.evaluation.normalized import reference_scores, normalized, policy_score
    refs = reference_scores(ds)                         # {"random": 0.03..., "expert": 1.0} on 500 pairs, seed 2024
    normalized(0.5, refs)                               # SPL 0.5 as a normalised score
    policy_score(policy, ds)["normalized"]              # a policy rolled out on the same pairs

**Raw metric: SPL** (success weighted by path length, :func:`dtradar_rl.evaluation.evaluate.spl`) over the twin's
seeded evaluation pairs (:func:`~dtradar_rl.evaluation.evaluate.sample_eval_pairs`, by default the 500 pairs of seed
2024 that ``make eval`` uses), each episode capped at the twin's step limit. Why SPL and not the return:

- it is bounded in [0, 1] and means the same on every twin (a path's length against the shortest one), so scores of
  different twins (cubicle, a Dallas quadrant) can be set side by side;
- the expert scores exactly 1 by definition (it walks a shortest path, so ``l / p = 1`` on every pair whose
  shortest path fits in the step limit, which holds for every connected pair with the default limit
  ``4 · (nx + ny)``), so 100 is well defined and no policy can exceed it;
- the return depends on the reward's shaping (``paper``, ``geodesic``, ... in :mod:`dtradar_rl.task.rewards`): the same
  behaviour would get another score under another reward, and the shaped rewards' scale changes with the twin.

**References** (:func:`reference_scores`), rolled out on the same pairs with
:func:`~dtradar_rl.evaluation.evaluate.rollout`:

- ``random``: a uniformly random move (X−, X+, Y−, Y+) at every step, from a torch generator seeded with ``seed``;
  its SPL is small but not zero (a random walk sometimes stumbles onto a near target);
- ``expert``: the breadth-first shortest-path move towards the target (:class:`ShortestPathOracle`, ties broken at
  random), noise-free. Its SPL is measured, not assumed, so a step limit too short for some pair shows.

They are cached per twin (name and content version, or the table's digest for a synthetic twin), pair count, seed and
step limit, in this process. :func:`logged_episodes_spl` is the same SPL computed from logged episodes (a logged
dataset's card reports both; see :mod:`dtradar_rl.offline.logged`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import unknown_name
from dtradar_data.store.logged import table_digest
from dtradar_rl.agents.policy import Policy
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs, spl
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.grid_mdp import GridMDP

#: The raw metric the normalised score rescales (see the module docstring for why).
METRIC = "spl"
#: The evaluation pairs of the normalised score: the count and seed of ``make eval``'s pairs.
DEFAULT_PAIRS = 500
DEFAULT_SEED = 2024
REFERENCES: tuple[str, ...] = ("random", "expert")

_CACHE: dict[tuple, dict[str, float]] = {}


class ShortestPathOracle:
    """Breadth-first shortest-path moves for every robot of a :class:`BatchedNavEnv` (the expert)."""

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
class ReferencePolicy(Policy):
    """A reference of the normalised score as a :class:`Policy` that :func:`rollout` runs: ``random`` (uniform
    moves) or ``expert`` (breadth-first shortest-path moves), seeded by ``seed`` (restarted by :meth:`env_for`)."""

    kind: str = "random"
    seed: int = 0
    _env: BatchedNavEnv | None = None
    _gen: torch.Generator | None = None
    _oracle: ShortestPathOracle | None = field(default=None, repr=False)

    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        self._env = BatchedNavEnv.from_dataset(ds, num_envs, obs=self.obs_preset, normalizer=self.normalizer, **kwargs)
        self._gen = torch.Generator(device=self._env.device)
        self._gen.manual_seed(self.seed)
        self._oracle = ShortestPathOracle(self._env) if self.kind == "expert" else None
        return self._env

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        if self._env is None:
            raise ConfigError("a reference policy acts only in the env it made (use evaluate.rollout)")
        if self._oracle is not None:
            return self._oracle.act(self._gen)
        return torch.randint(4, (self._env.num_envs,), generator=self._gen, device=self._env.device)


def reference_policy(kind: str, seed: int = 0) -> ReferencePolicy:
    """The ``random`` or ``expert`` reference (they read no observation: the ``goal`` preset, unnormalised)."""
    if kind not in REFERENCES:
        raise unknown_name("reference policy", kind, REFERENCES)
    return ReferencePolicy(q=None, config=None, normalizer=None, obs_preset="goal", meta={}, kind=kind, seed=seed)


def twin_key(ds: Dataset) -> str:
    """What identifies a twin's content: ``name@version``, or its table's digest when it has no stored version."""
    return f"{ds.name}@{ds.version or table_digest(ds.table)}"


def reference_scores(
    ds: Dataset,
    *,
    pairs: int = DEFAULT_PAIRS,
    seed: int = DEFAULT_SEED,
    max_steps: int | None = None,
    device: str = "cpu",
) -> dict[str, float]:
    """``{"random": x, "expert": y}``: the SPL of the two references on ``pairs`` seeded pairs of ``ds`` (``seed``
    draws the pairs and the random policy's moves); cached in this process per twin content, pairs, seed and step
    limit (``max_steps``: None = the twin's default)."""
    key = (twin_key(ds), int(pairs), int(seed), int(max_steps or 0))
    if key not in _CACHE:
        eval_pairs = sample_eval_pairs(ds, pairs, seed)
        out = {}
        for kind in REFERENCES:
            r = rollout(reference_policy(kind, seed), ds, eval_pairs, max_steps=max_steps, device=device)
            out[kind] = metrics_from_rollouts(r).spl
        _CACHE[key] = out
    return dict(_CACHE[key])


def normalized(value: float, refs: dict[str, float]) -> float:
    """``100 · (value − random) / (expert − random)``: 0 at the random reference, 100 at the expert, linear (so
    strictly increasing) in between and beyond."""
    lo, hi = float(refs["random"]), float(refs["expert"])
    if not hi > lo:
        raise ConfigError(
            f"the expert's {METRIC} ({hi:.4f}) does not exceed the random policy's ({lo:.4f}): no normalised score",
            hint="check the twin's step limit (--max-steps) and its connected cells",
        )
    return 100.0 * (float(value) - lo) / (hi - lo)


def policy_score(
    policy: Policy,
    ds: Dataset,
    *,
    pairs: int = DEFAULT_PAIRS,
    seed: int = DEFAULT_SEED,
    max_steps: int | None = None,
    device: str = "cpu",
) -> dict[str, Any]:
    """``policy`` rolled out on the normalised score's pairs of ``ds``: its success rate, SPL, normalised score and
    the references, with how they were measured (a card's record)."""
    refs = reference_scores(ds, pairs=pairs, seed=seed, max_steps=max_steps, device=device)
    r = rollout(policy, ds, sample_eval_pairs(ds, pairs, seed), max_steps=max_steps, device=device)
    m = metrics_from_rollouts(r)
    return {
        "metric": METRIC,
        "source": "rollout",
        "pairs": int(pairs),
        "seed": int(seed),
        "success_rate": m.success_rate,
        "spl": m.spl,
        "normalized": normalized(m.spl, refs),
        "references": refs,
    }


def logged_episodes_spl(
    ds: Dataset,
    *,
    episode: np.ndarray,
    robot: np.ndarray,
    cell: np.ndarray,
    action: np.ndarray,
    target: np.ndarray,
    terminated: np.ndarray,
    max_steps: int,
    snapshot: np.ndarray | None = None,
) -> dict[str, Any]:
    """The SPL of logged episodes (columns of a transition table: episodes contiguous, each robot's stream
    contiguous) on ``ds``: per episode success, the breadth-first shortest length from its first cell and the cells
    actually travelled (a collision travels nothing). On a moving twin, given each step's ``snapshot``, as evaluation
    measures it there: the shortest path in time from the first cell at the episode's first snapshot (waits allowed)
    against the steps taken (a bump into a mover costs a step: the static map alone cannot tell it from a move).

    Only the episodes that started at least ``max_steps`` (the log's step limit) before the end of their robot's
    stream count (``selection`` ``"started-early"``): each of them finished (reached its target or hit the limit)
    whatever its length, so long episodes are not under-represented, as they would be among all the finished ones of
    a log that is short next to the step limit. When no episode started that early (every robot logged fewer than
    ``max_steps`` steps, e.g. a short training run's replay buffer), the finished episodes count instead
    (``selection`` ``"finished"``: target reached or step limit hit, not cut by the end of logging), which favours
    the short, successful ones. Returns ``{"spl", "success_rate", "episodes", "selection"}`` (NaN when no episode
    finished)."""
    mdp = GridMDP.from_dataset(ds)
    episode, robot, cell = np.asarray(episode), np.asarray(robot), np.asarray(cell)
    n_ep = int(episode.max()) + 1 if episode.size else 0
    first = np.r_[True, episode[1:] != episode[:-1]]
    last = np.r_[episode[1:] != episode[:-1], True]
    # each row's position in its robot's stream, and the stream's length
    robot_start = np.r_[True, robot[1:] != robot[:-1]]
    starts = np.flatnonzero(robot_start)
    stream = np.diff(np.r_[starts, robot.size])
    pos = np.arange(robot.size) - np.repeat(starts, stream)
    keep = (pos + max_steps <= np.repeat(stream, stream))[first]
    start, tgt = cell[first], np.asarray(target)[first]
    targets, row = np.unique(tgt, return_inverse=True)
    if snapshot is not None and ds.is_moving:
        travelled = np.bincount(episode, minlength=n_ep).astype(np.float64)  # steps, as evaluation counts them
        t0 = np.asarray(snapshot)[first]
        shortest = mdp.space_time_distances_many(targets)[row, t0, start].astype(np.int64) if n_ep else np.zeros(0)
    else:
        moved = mdp.next_cell[cell, np.asarray(action)] != cell
        travelled = np.bincount(episode, weights=moved.astype(np.float64), minlength=n_ep)
        shortest = mdp.bfs_distances_many(targets)[row, start] if n_ep else np.zeros(0)
    success = np.asarray(terminated)[last]
    selection = "started-early"
    if not keep.any():
        lengths = np.bincount(episode, minlength=n_ep)
        keep, selection = success | (lengths >= max_steps), "finished"
    keep &= shortest >= 0  # a start that movers cut off from its target in time has no shortest path
    if not keep.any():
        return {"spl": float("nan"), "success_rate": float("nan"), "episodes": 0, "selection": selection}
    return {
        "spl": spl(success[keep], shortest[keep], travelled[keep]),
        "success_rate": float(success[keep].mean()),
        "episodes": int(keep.sum()),
        "selection": selection,
    }


__all__ = [
    "DEFAULT_PAIRS",
    "DEFAULT_SEED",
    "METRIC",
    "REFERENCES",
    "ReferencePolicy",
    "ShortestPathOracle",
    "logged_episodes_spl",
    "normalized",
    "policy_score",
    "reference_policy",
    "reference_scores",
    "twin_key",
]
