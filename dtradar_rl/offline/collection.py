"""The one rollout engine that logs offline-RL data: a behaviour policy (:mod:`dtradar_rl.offline.behaviours`) acting
for every robot of a batched env.

:func:`roll` runs a behaviour for about ``steps`` environment steps (rounded up to whole steps of all robots) and
returns numpy arrays robot by robot, every episode contiguous, with the observation before and after each move (and,
on a moving twin, the snapshot each step starts in: ``snapshot``). The
last step of each episode is ``terminated`` (target reached) or ``truncated`` (the step limit, or the logging budget
ending mid-episode), never both. Nothing is dropped.

:func:`replay` turns an online DQN run's replay buffer (the ``medium-replay`` family) into the same columns: it steps a
fresh env built like the run's with the buffer's actions, which gives the cells, targets and truncations the buffer
does not keep, and checks every observation, reward and terminal against the buffer's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import CorruptDatasetError
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.honest import HonestNavEnv
from dtradar_rl.offline.behaviours import Actor, BehaviourSpec, checkpoint_policy
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.sensing import Readings, sensing_for
from dtradar_rl.train.replay import replay_transitions

#: Bytes per logged step of each column :func:`roll` records, as it records them (torch's dtypes: ``obs`` and
#: ``next_obs`` float32 per observation column, moves, cells and targets int64, rewards float32, flags bool)...
RECORDED_BYTES: dict[str, int] = {
    "action": 8,
    "reward": 4,
    "terminated": 1,
    "truncated": 1,
    "cell": 8,
    "target": 8,
}
#: ... and of the columns :func:`_assemble` adds (int64 each).
ASSEMBLED_BYTES: dict[str, int] = {"episode": 8, "step": 8, "robot": 8, "component": 8}
#: Bytes per step per observation column: ``obs`` and ``next_obs``, float32 each.
OBS_BYTES = 2 * 4


def rollout_steps(steps: int, num_envs: int) -> int:
    """The steps :func:`roll` logs for ``steps``: rounded up to whole steps of all ``num_envs`` robots."""
    return -(-int(steps) // int(num_envs)) * int(num_envs)


def rollout_bytes(steps: int, num_envs: int, obs_width: int) -> int:
    """The memory :func:`roll` holds at its peak for ``steps`` (:func:`rollout_steps`) of ``obs_width``-wide
    observations: every recorded step stays in memory until the end, and :func:`_assemble` stacks the recorded steps
    into columns while they are still held (two copies), then adds its own columns. A lower bound: the store's table
    and the interpreter come on top, so a log refused by it cannot fit."""
    recorded = OBS_BYTES * int(obs_width) + sum(RECORDED_BYTES.values())
    return rollout_steps(steps, num_envs) * (2 * recorded + sum(ASSEMBLED_BYTES.values()))


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
    sensing: str = "privileged",
    sensing_noise: str = "realistic",
) -> Rollout:
    """Run ``spec`` on ``ds`` for ``ceil(steps / num_envs)`` steps of all robots; see the module docstring.

    With an honest ``sensing`` (:mod:`dtradar_rl.task.sensing`) the recorded ``obs``/``next_obs`` are what the robot's
    own sensors read (:class:`~dtradar_rl.envs.honest.HonestNavEnv`, receiver noise ``sensing_noise``); the behaviour
    still acts on the env's own observation (a data collector may be privileged: the learner never sees it), so the
    same seed logs the same moves whatever is recorded. Every new episode switches the robot on afresh."""
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
    actor = Actor(spec, env, gen, policy=checkpoint_policy(spec, obs, normalizer, device, ds=ds))
    honest = None
    if not sensing_for(sensing).privileged:
        honest = HonestNavEnv(env, Readings.from_dataset(ds), sensing, sensing_noise, seed)
    horizon = -(-steps // num_envs)
    rec = _recorder(env)
    o = env.reset()
    seen = honest.observe() if honest is not None else o  # what is recorded as the robot's observation
    for _ in range(horizon):
        a = actor(o)
        _record_where(rec, env)
        next_o, r, term, trunc, _ = (honest or env).step(a)
        rec["obs"].append(seen)
        rec["action"].append(a)
        rec["reward"].append(r)
        rec["next_obs"].append(next_o)
        rec["terminated"].append(term)
        rec["truncated"].append(trunc & ~term)
        if actor.walk is not None:  # an OGBench-style family starts its own episodes (dtradar_rl.offline.walks)
            actor.walk.next_episodes(term, trunc & ~term)
        else:
            env.reset_where(term | trunc)
        o = env.observe()
        if honest is not None:
            honest.switched_on(term | trunc)
            seen = honest.observe()
        else:
            seen = o

    return _assemble(rec, num_envs, horizon, actor.component.cpu().numpy(), t0)


def _recorder(env: BatchedNavEnv) -> dict[str, list[torch.Tensor]]:
    """The per-step lists a rollout fills; on a moving twin also ``snapshot``, the snapshot each step starts in (the
    transition table has no column for it: :mod:`dtradar_rl.offline.moving_logs` keeps it in the meta)."""
    keys = ("obs", "action", "reward", "next_obs", "terminated", "truncated", "cell", "target")
    return {k: [] for k in keys + (("snapshot",) if env.moving else ())}


def _record_where(rec: dict[str, list[torch.Tensor]], env: BatchedNavEnv) -> None:
    """Record where every robot is before its move: its cell, its target and, on a moving twin, its snapshot."""
    rec["cell"].append(env.cell.clone())
    rec["target"].append(env.target.clone())
    if "snapshot" in rec:
        rec["snapshot"].append(env.t.clone())


def _assemble(rec: dict[str, list[torch.Tensor]], n: int, horizon: int, component: np.ndarray, t0: float) -> Rollout:
    """Steps recorded step by step for ``n`` robots as columns robot by robot, every unfinished episode truncated by
    the end of logging, with episode and step numbers."""

    def stack(xs):  # [step, robot, ...] -> [robot, step, ...]
        return torch.stack(xs, 1).cpu().numpy()

    cols = {k: stack(v) for k, v in rec.items()}
    cut = ~(cols["terminated"][:, -1] | cols["truncated"][:, -1])
    cols["truncated"][:, -1] |= cut  # the logging budget ends every unfinished episode: a truncation
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
        "component": np.repeat(component, horizon),
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


def replay(
    ds: Dataset,
    buffer: dict[str, Any],
    *,
    num_envs: int,
    obs: str = "neighbors",
    normalizer: Normalizer | None = None,
    reward: str = "geodesic",
    max_steps: int | None = None,
    seed: int = 0,
    device: str = "cpu",
) -> Rollout:
    """The transitions of an online DQN run's replay buffer (``buffer``: :meth:`ReplayBuffer.state_dict` of a run with
    ``num_envs`` robots, ``seed``, and no obstacle augmentation, memory or noise, whose buffer never wrapped) as
    :func:`roll`'s columns. The run added one batch of ``num_envs`` transitions per step, robot by robot, so a fresh env
    built like the run's and stepped with the buffer's actions passes through the same states (the env draws its pairs
    from its own seeded generator); each observation, reward and terminal must equal the buffer's, else
    :class:`CorruptDatasetError`. The stored columns are the buffer's own; cells, targets and truncations come from the
    replayed env; the episodes running at the end are truncated by the end of logging."""
    t0 = time.perf_counter()
    tr = replay_transitions(buffer)
    n = int(num_envs)
    size = len(tr["action"])
    if size == 0 or size % n:
        raise CorruptDatasetError(
            f"a replay buffer of {size} transitions is not whole steps of {n} robots",
            hint="replay the buffer of a run that never wrapped, with the run's --num-envs",
        )
    horizon = size // n
    normalizer = normalizer or Normalizer.fit(ds)
    env = BatchedNavEnv.from_dataset(
        ds, n, obs=obs, normalizer=normalizer, reward=reward, max_steps=max_steps or None, device=device, seed=seed
    )
    as_t = lambda x: torch.as_tensor(x, device=env.device)  # noqa: E731
    rec = _recorder(env)
    env.reset()
    for t in range(horizon):
        rows = slice(t * n, (t + 1) * n)
        o, a = as_t(tr["obs"][rows]), as_t(tr["action"][rows]).long()
        _record_where(rec, env)
        seen = env.observe()
        next_o, r, term, trunc, _ = env.step(a)
        same = (
            torch.equal(seen, o)
            and torch.equal(next_o, as_t(tr["next_obs"][rows]))
            and torch.equal(r, as_t(tr["reward"][rows]))
            and torch.equal(term, as_t(tr["terminated"][rows]))
        )
        if not same:
            raise CorruptDatasetError(
                f"the replay buffer differs from its run at step {t} (transitions {rows.start}..{rows.stop - 1}): "
                "it was not collected on this twin with these settings",
                hint="replay it with the run's twin, --num-envs, --obs, --reward, --max-steps and --seed",
            )
        rec["obs"].append(o)
        rec["action"].append(a)
        rec["reward"].append(r)
        rec["next_obs"].append(next_o)
        rec["terminated"].append(term)
        rec["truncated"].append(trunc & ~term)
        env.reset_where(term | trunc)
    out = _assemble(rec, n, horizon, np.zeros(n, np.int64), t0)
    out.stats["source"] = "replay buffer"
    return out


__all__ = ["Rollout", "replay", "roll", "rollout_bytes", "rollout_steps"]
