"""The replay buffer of the online DQN: preallocated tensors in a ring, sampled uniformly."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch


class ReplayBuffer:
    """A ring buffer of transitions ``(obs, action, reward, next_obs, terminated, expert)`` as preallocated tensors
    (``expert``: ``bool[4]`` or ``bool[5]``, the actions a shortest path would take; kept, and allocated, only when
    :meth:`add` is given them, else ``None``)."""

    def __init__(self, capacity: int, obs_dim: int, device: torch.device):
        self.capacity, self.ptr, self.size = capacity, 0, 0
        self.obs = torch.zeros((capacity, obs_dim), device=device)
        self.next_obs = torch.zeros((capacity, obs_dim), device=device)
        self.action = torch.zeros(capacity, dtype=torch.long, device=device)
        self.reward = torch.zeros(capacity, device=device)
        self.terminated = torch.zeros(capacity, device=device)
        self.expert: torch.Tensor | None = None

    def add(self, obs, action, reward, next_obs, terminated, expert=None) -> None:
        n = obs.shape[0]
        idx = (self.ptr + torch.arange(n, device=obs.device)) % self.capacity
        self.obs[idx], self.next_obs[idx] = obs, next_obs
        self.action[idx], self.reward[idx], self.terminated[idx] = action, reward, terminated.float()
        if expert is not None:
            if self.expert is None:  # one column per expert action: 4 moves, 5 with a moving twin's wait
                self.expert = torch.zeros((self.capacity, expert.shape[1]), dtype=torch.bool, device=self.obs.device)
            self.expert[idx] = expert
        self.ptr = (self.ptr + n) % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int, gen: torch.Generator):
        idx = torch.randint(self.size, (batch_size,), generator=gen, device=self.obs.device)
        return (
            self.obs[idx],
            self.action[idx],
            self.reward[idx],
            self.next_obs[idx],
            self.terminated[idx],
            None if self.expert is None else self.expert[idx],
        )

    def state_dict(self) -> dict[str, Any]:
        n = self.size
        state = {
            "ptr": self.ptr,
            "size": n,
            "obs": self.obs[:n].clone(),
            "next_obs": self.next_obs[:n].clone(),
            "action": self.action[:n].clone(),
            "reward": self.reward[:n].clone(),
            "terminated": self.terminated[:n].clone(),
        }
        if self.expert is not None:
            state["expert"] = self.expert[:n].clone()
        return state

    def load_state_dict(self, s: dict[str, Any]) -> None:
        n = s["size"]
        self.ptr, self.size = s["ptr"], n
        for k in ("obs", "next_obs", "action", "reward", "terminated"):
            getattr(self, k)[:n] = s[k]
        if "expert" in s:
            width = s["expert"].shape[1]
            self.expert = torch.zeros((self.capacity, width), dtype=torch.bool, device=self.obs.device)
            self.expert[:n] = s["expert"]


def replay_transitions(state: dict[str, Any]) -> dict[str, np.ndarray]:
    """The transitions of a saved buffer (:meth:`ReplayBuffer.state_dict`, e.g. ``last.pt["replay"]``) as numpy arrays
    in the order they were added, oldest first (``obs``/``next_obs`` float32[N, D], ``action`` int64, ``reward``
    float32, ``terminated`` bool; ``expert`` bool[N, 4] when kept). A buffer that wrapped holds only the newest
    ``capacity`` transitions: its ``size`` then equals its capacity and ``ptr`` marks the oldest."""
    n, ptr = int(state["size"]), int(state["ptr"])
    # not full: the ring was filled from 0 and ptr == size; full (ptr < capacity == size): ptr is the oldest entry
    start = 0 if ptr == n else ptr
    order = (np.arange(n) + start) % max(n, 1)
    out = {}
    for k in ("obs", "next_obs", "action", "reward", "terminated", "expert"):
        if k in state:
            out[k] = state[k].detach().cpu().numpy()[order]
    out["terminated"] = out["terminated"] > 0.5
    out["obs"], out["next_obs"] = out["obs"].astype(np.float32), out["next_obs"].astype(np.float32)
    out["reward"] = out["reward"].astype(np.float32)
    return out


__all__ = ["ReplayBuffer", "replay_transitions"]
