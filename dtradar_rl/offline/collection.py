"""The one rollout engine that logs offline-RL data: a behaviour policy (:mod:`dtradar_rl.offline.behaviours`) acting
for every robot of a batched env.

:func:`roll` runs a behaviour for about ``steps`` environment steps (rounded up to whole steps of all robots) and
returns numpy arrays robot by robot, every episode contiguous, with the observation before and after each move. The
last step of each episode is ``terminated`` (target reached) or ``truncated`` (the step limit, or the logging budget
ending mid-episode), never both. Nothing is dropped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.offline.behaviours import Actor, BehaviourSpec, checkpoint_policy
from dtradar_rl.task.observations import Normalizer


@dataclass
class Rollout:
    """Logged steps robot by robot (``obs``/``next_obs`` float32[T, D]) and how the log went."""

    columns: dict[str, np.ndarray]
    stats: dict[str, Any]


def roll(
    ds: Dataset,
    spec: BehaviourSpec,
    *,
    steps: int,
    num_envs: int = 256,
    obs: str = "neighbors",
    normalizer: Normalizer | None = None,
    reward: str = "geodesic",
    max_steps: int | None = None,
    seed: int = 0,
    device: str = "cpu",
) -> Rollout:
    """Run ``spec`` on ``ds`` for ``ceil(steps / num_envs)`` steps of all robots; see the module docstring."""
    spec.validate()
    t0 = time.perf_counter()
    normalizer = normalizer or Normalizer.fit(ds)
    env = BatchedNavEnv.from_dataset(
        ds,
        num_envs,
        obs=obs,
        normalizer=normalizer,
        reward=reward,
        max_steps=max_steps or None,
        device=device,
        seed=seed,
    )
    gen = torch.Generator(device=env.device)
    gen.manual_seed(seed + 1)
    actor = Actor(spec, env, gen, policy=checkpoint_policy(spec, obs, normalizer, device))
    horizon = -(-steps // num_envs)
    keys = ("obs", "action", "reward", "next_obs", "terminated", "truncated", "cell", "target")
    rec: dict[str, list[torch.Tensor]] = {k: [] for k in keys}
    o = env.reset()
    for _ in range(horizon):
        a = actor(o)
        rec["cell"].append(env.cell.clone())
        rec["target"].append(env.target.clone())
        next_o, r, term, trunc, _ = env.step(a)
        rec["obs"].append(o)
        rec["action"].append(a)
        rec["reward"].append(r)
        rec["next_obs"].append(next_o)
        rec["terminated"].append(term)
        rec["truncated"].append(trunc & ~term)
        env.reset_where(term | trunc)
        o = env.observe()

    def stack(xs):  # [step, robot, ...] -> [robot, step, ...]
        return torch.stack(xs, 1).cpu().numpy()

    cols = {k: stack(v) for k, v in rec.items()}
    cut = ~(cols["terminated"][:, -1] | cols["truncated"][:, -1])
    cols["truncated"][:, -1] |= cut  # the logging budget ends every unfinished episode: a truncation
    n = num_envs
    flat = {k: v.reshape(n * horizon, *v.shape[2:]) for k, v in cols.items()}
    ends = flat["terminated"] | flat["truncated"]
    episode = np.r_[0, np.cumsum(ends)[:-1]].astype(np.int64)
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]])
    step = np.arange(len(episode)) - np.repeat(starts, np.diff(np.r_[starts, len(episode)]))
    out = {
        **flat,
        "episode": episode,
        "step": step,
        "robot": np.repeat(np.arange(n), horizon),
        "component": np.repeat(actor.component.cpu().numpy(), horizon),
    }
    stats = {
        "robots": n,
        "horizon": horizon,
        "steps": int(n * horizon),
        "episodes": int(ends.sum()),
        "terminated": int(flat["terminated"].sum()),
        "truncated_step_limit": int(cols["truncated"].sum() - cut.sum()),
        "truncated_end_of_log": int(cut.sum()),
        "wall_s": time.perf_counter() - t0,
    }
    return Rollout(out, stats)


__all__ = ["Rollout", "roll"]
