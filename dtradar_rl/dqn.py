"""Deep Q-learning on a dataset's navigation MDP, readable top to bottom (after CleanRL's ``dqn.py``).

    from dtradar_rl.dqn import config_for, train
    result = train(config_for("tuned", scene="synthetic", total_env_steps=100_000))
    result.checkpoint   # runs/synthetic/dqn/model.pt, with config.json, curves.csv and curves.png beside it

Three presets (:data:`PRESETS`, :func:`config_for`):

``paper``  the paper's agent: ``paper`` observations (no target), ``paper`` reward, 5 dense ReLU layers of 256,
           γ = 0.9, constant ε = 0.1, one environment, one gradient update per step, 500 episodes indoor / 80
           outdoor. Kept for reproduction; with random targets and no target in the state it cannot learn to reach
           them (see :mod:`dtradar_rl.observations`).
``tuned``  the default: ``neighbors`` observations (goal-conditioned, senses blocked neighbours), ``geodesic``
           shaped reward, Double DQN, 2 x 256 hidden units, γ = 0.5, 256 robots in the batched torch environment,
           ε decaying 1 → 0.05 over 40 % of the budget, Adam 1e-3 decaying linearly to 1e-4, and one gradient update
           (batch 512) per 48 environment steps, so the paper's 600 K-step budget (~12 K updates) trains in under a
           minute on two CPU cores (updates, not the table lookups, bound the speed).
``robust`` ``tuned`` + obstacle augmentation (domain randomisation, :mod:`dtradar_rl.batched`): at every episode
           reset each robot gets 10 random extra obstacles of 1 x 1 to 2 x 2 cells on the training twin, which
           collide and read as blocked neighbours, with the geodesic potential replanned around them. The agent
           learns to read its neighbours' has-radio flags and detour. On the real cubicle twin (600 K steps, seeds
           0-2) it lifts blueprint -> dynamic success from 0.67-0.70 (0.68-0.74 with the shield) to 0.79-0.82 with
           no collisions, keeps blueprint success >= 0.99 (SPL >= 0.99) and trains ~14 % slower (52 s vs 46 s on 2
           idle cores). What it cannot fix: the dynamic twin's changed radio features (~5 points) and detours a
           memoryless policy cannot plan from its 4 neighbours alone.

The loop: every robot acts ε-greedily, the batch of transitions goes into a replay buffer, finished robots are
reset; every ``env_steps_per_update`` environment steps one Huber-loss update on a random minibatch follows, with
targets from a target network copied every ``target_update_every`` updates. Checkpoints carry the config and the
feature normaliser; ``last.pt`` also carries optimiser, replay buffer and random states, so ``resume=True``
continues a run exactly where it stopped.
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, unknown_name

from .batched import AUG_POTENTIALS, BatchedNavEnv
from .data import is_synthetic, load_dataset
from .mdp import check_reward
from .observations import Normalizer, build_observations, check_preset

CHECKPOINT_FORMAT = "dtradar-dqn/1"
INDOOR_SCENES = ("cubicle", "meeting")


class ConfigError(DtradarError, ValueError):
    """A training or evaluation setting that is out of range."""


class CheckpointError(DtradarError, FileNotFoundError):
    """A checkpoint that is missing or not a dtradar DQN checkpoint."""


@dataclass(frozen=True)
class DQNConfig:
    """Deep Q-learning on the navigation MDP of one dataset (defaults: the ``tuned`` preset)."""

    scene: str = "cubicle"
    """scene to train on; the dataset is <scene>/<variant> (synthetic = a 42x18 stand-in, no ray tracer)"""
    variant: str = "blueprint"
    """twin to train on (the paper trains on the blueprint)"""
    revision: str | None = None
    """dataset version tag or hash (default: the newest)"""
    preset: str = "tuned"
    """the preset these settings started from (tuned, robust or paper); recorded in config.json"""
    obs: str = "neighbors"
    """observation preset: paper (10 inputs, no target), goal (+ target), neighbors (+ neighbouring cells' radio)"""
    reward: str = "geodesic"
    """reward: paper (exact), scaled, euclidean or geodesic (shaped; see dtradar_rl.mdp)"""
    max_steps: int = 0
    """episode step limit (truncation); 0 = 4 * (nx + ny)"""
    num_envs: int = 256
    """robots stepped together in the batched environment"""
    aug_obstacles: int = 0
    """obstacle augmentation: extra random obstacles per robot, redrawn at every episode reset, that collide and
    read as blocked neighbours (0 = off; see dtradar_rl.batched)"""
    aug_obstacle_size: int = 2
    """largest side of an extra obstacle in cells (each is a 1..size x 1..size rectangle; 2 = 1 m at 0.5 m cells)"""
    aug_potential: str = "replan"
    """geodesic shaping with extra obstacles: replan (BFS per robot on its augmented grid) or blueprint"""
    total_env_steps: int = 600_000
    """training budget in environment steps (all robots together); the paper's is 600K"""
    episodes: int = 0
    """also stop after this many finished episodes (0 = no limit; the paper: 500 indoor, 80 outdoor)"""
    hidden: tuple[int, ...] = (256, 256)
    """sizes of the dense ReLU hidden layers"""
    lr: float = 1e-3
    """Adam learning rate"""
    lr_end: float = 1e-4
    """learning rate at the end of the budget, reached linearly (negative = constant lr)"""
    gamma: float = 0.5
    """discount factor (the paper: 0.9; with the geodesic reward every step is informative, so a short horizon
    learns faster and keeps the shortest-path optimum)"""
    batch_size: int = 512
    """minibatch size of one gradient update"""
    buffer_size: int = 200_000
    """replay buffer capacity (transitions)"""
    learning_starts: int = 10_000
    """environment steps collected before the first update"""
    env_steps_per_update: int = 48
    """environment steps per gradient update (1 = an update every step, as in the paper)"""
    target_update_every: int = 250
    """copy the online network into the target network every this many updates"""
    double_dqn: bool = True
    """Double DQN targets (the online network picks the next action, the target network values it)"""
    eps_start: float = 1.0
    """initial exploration rate"""
    eps_end: float = 0.05
    """final exploration rate"""
    eps_decay_fraction: float = 0.4
    """fraction of the budget over which exploration decays linearly from eps_start to eps_end"""
    max_grad_norm: float = 10.0
    """gradient-norm clipping (0 = off)"""
    seed: int = 0
    """seed of the network, the environment and exploration"""
    device: str = "cpu"
    """torch device (cpu, cuda)"""
    threads: int = 0
    """torch CPU threads (0 = auto: up to 2, fewer when other processes keep cores busy; see auto_threads)"""
    out: str = ""
    """output directory (default runs/<scene>/dqn)"""
    checkpoint_every: int = 200_000
    """write last.pt every this many environment steps (0 = only at the end)"""
    save_replay: bool = True
    """include the replay buffer in last.pt, so a resumed run is exact"""
    resume: bool = False
    """continue from <out>/last.pt up to the (possibly raised) budget (exploration follows the new budget)"""
    verbose: bool = True
    """print progress"""

    @property
    def dataset_name(self) -> str:
        return f"{self.scene}/{self.variant}" + (f"@{self.revision}" if self.revision else "")

    @property
    def out_dir(self) -> Path:
        return Path(self.out or f"runs/{self.scene}/dqn")

    def validate(self) -> DQNConfig:
        check_preset(self.obs)
        check_reward(self.reward)
        if self.preset not in PRESETS:
            raise unknown_name("training preset", self.preset, PRESETS)
        positive = ("num_envs", "total_env_steps", "batch_size", "buffer_size", "env_steps_per_update",
                    "target_update_every")
        for name in positive:
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.aug_obstacles < 0 or self.aug_obstacle_size < 1:
            raise ConfigError(f"aug_obstacles must be >= 0 and aug_obstacle_size >= 1, got {self.aug_obstacles} "
                              f"and {self.aug_obstacle_size}")
        if self.aug_potential not in AUG_POTENTIALS:
            raise unknown_name("augmentation potential", self.aug_potential, AUG_POTENTIALS)
        if self.threads < 0:
            raise ConfigError(f"threads must be >= 0 (0 = auto), got {self.threads}")
        if not 0 < self.gamma < 1:
            raise ConfigError(f"gamma must be in (0, 1), got {self.gamma}")
        for name in ("eps_start", "eps_end", "eps_decay_fraction"):
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        if not self.hidden or min(self.hidden) < 1:
            raise ConfigError(f"hidden must list positive layer sizes, got {self.hidden}")
        return self

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> DQNConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        d = {k: (tuple(v) if k == "hidden" else v) for k, v in d.items() if k in names}
        return cls(**d)


PRESETS: dict[str, dict[str, Any]] = {
    "tuned": {},
    "robust": {"aug_obstacles": 10, "aug_obstacle_size": 2, "aug_potential": "replan"},
    "paper": dict(obs="paper", reward="paper", num_envs=1, episodes=500, hidden=(256,) * 5, lr=1e-3, lr_end=-1.0,
                  gamma=0.9,
                  batch_size=64, buffer_size=100_000, learning_starts=1_000, env_steps_per_update=1,
                  target_update_every=500, double_dqn=False, eps_start=0.1, eps_end=0.1),
}


def config_for(preset: str = "tuned", **overrides) -> DQNConfig:
    """The config of a preset, with ``overrides``; the paper preset uses 80 episodes for outdoor scenes."""
    if preset not in PRESETS:
        raise unknown_name("training preset", preset, PRESETS)
    values = {**PRESETS[preset], "preset": preset}
    scene = overrides.get("scene", DQNConfig.scene)
    if preset == "paper" and scene.split("-")[0] not in INDOOR_SCENES and not is_synthetic(scene):
        values["episodes"] = 80
    return DQNConfig(**{**values, **overrides}).validate()


# -- network and replay buffer -------------------------------------------------------------------------------------
class QNetwork(nn.Module):
    """``obs -> [Linear, ReLU] x len(hidden) -> Linear -> 4 action values``."""

    def __init__(self, in_dim: int, hidden: tuple[int, ...], n_actions: int = 4):
        super().__init__()
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(in_dim, h), nn.ReLU()]
            in_dim = h
        layers.append(nn.Linear(in_dim, n_actions))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class ReplayBuffer:
    """A ring buffer of transitions ``(obs, action, reward, next_obs, terminated)`` as preallocated tensors."""

    def __init__(self, capacity: int, obs_dim: int, device: torch.device):
        self.capacity, self.ptr, self.size = capacity, 0, 0
        self.obs = torch.zeros((capacity, obs_dim), device=device)
        self.next_obs = torch.zeros((capacity, obs_dim), device=device)
        self.action = torch.zeros(capacity, dtype=torch.long, device=device)
        self.reward = torch.zeros(capacity, device=device)
        self.terminated = torch.zeros(capacity, device=device)

    def add(self, obs, action, reward, next_obs, terminated) -> None:
        n = obs.shape[0]
        idx = (self.ptr + torch.arange(n, device=obs.device)) % self.capacity
        self.obs[idx], self.next_obs[idx] = obs, next_obs
        self.action[idx], self.reward[idx], self.terminated[idx] = action, reward, terminated.float()
        self.ptr = (self.ptr + n) % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int, gen: torch.Generator):
        idx = torch.randint(self.size, (batch_size,), generator=gen, device=self.obs.device)
        return self.obs[idx], self.action[idx], self.reward[idx], self.next_obs[idx], self.terminated[idx]

    def state_dict(self) -> dict[str, Any]:
        n = self.size
        return {"ptr": self.ptr, "size": n, "obs": self.obs[:n].clone(), "next_obs": self.next_obs[:n].clone(),
                "action": self.action[:n].clone(), "reward": self.reward[:n].clone(),
                "terminated": self.terminated[:n].clone()}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        n = s["size"]
        self.ptr, self.size = s["ptr"], n
        for k in ("obs", "next_obs", "action", "reward", "terminated"):
            getattr(self, k)[:n] = s[k]


# -- training ------------------------------------------------------------------------------------------------------
@dataclass
class TrainResult:
    """What :func:`train` returns: where things were written and how the run went."""

    checkpoint: Path
    out_dir: Path
    env_steps: int
    updates: int
    episodes: int
    wall_s: float
    #: success rate, mean reward, steps and collisions over the last 10 % of training episodes
    final: dict[str, float] = field(default_factory=dict)


def idle_cores(interval_s: float = 0.25) -> float:
    """Cores left idle by other processes right now (from ``/proc/stat`` over ``interval_s``; Linux), else from
    the 1-minute load average."""
    def snapshot():
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
        return v[3] + v[4], sum(v)  # idle + iowait, total

    cores = os.cpu_count() or 1
    try:
        (i0, t0), _ = snapshot(), time.sleep(interval_s)
        i1, t1 = snapshot()
        return cores * (i1 - i0) / max(1, t1 - t0)
    except (OSError, ValueError, IndexError):
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
        return max(0.0, cores - load)


def auto_threads(max_threads: int = 2) -> int:
    """Torch threads for small networks: ``max_threads`` on an idle machine, fewer when other processes keep cores
    busy. Measured on 2 cores: with another busy process, 2 torch threads collapse to ~5 % of the 1-thread speed
    (the threads wait on each other), while on an idle machine 2 threads are ~1.5x faster than 1.
    """
    return max(1, min(max_threads, int(round(idle_cores()))))


def epsilon(cfg: DQNConfig, env_steps: int) -> float:
    """Linear decay from ``eps_start`` to ``eps_end`` over ``eps_decay_fraction`` of the budget."""
    span = cfg.eps_decay_fraction * cfg.total_env_steps
    frac = 1.0 if span <= 0 else min(1.0, env_steps / span)
    return cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)


def train(config: DQNConfig, dataset: Dataset | None = None) -> TrainResult:
    """Train a DQN agent on ``dataset`` (default: load ``config.dataset_name``); write checkpoints and curves."""
    cfg = config.validate()
    t_start = time.perf_counter()
    torch.set_num_threads(cfg.threads or auto_threads())
    torch.set_flush_denormal(True)  # tiny Adam moments otherwise slow every CPU update down several-fold
    torch.manual_seed(cfg.seed)
    device = torch.device(cfg.device)
    out = cfg.out_dir
    out.mkdir(parents=True, exist_ok=True)
    write_config(cfg, out)

    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    normalizer = Normalizer.fit(ds)
    env = BatchedNavEnv.from_dataset(ds, cfg.num_envs, obs=cfg.obs, normalizer=normalizer, reward=cfg.reward,
                                     max_steps=cfg.max_steps or None, device=device, seed=cfg.seed,
                                     aug_obstacles=cfg.aug_obstacles, aug_obstacle_size=cfg.aug_obstacle_size,
                                     aug_potential=cfg.aug_potential)
    q = QNetwork(env.obs_dim, cfg.hidden).to(device)
    q_target = copy.deepcopy(q)
    optimizer = torch.optim.Adam(q.parameters(), lr=cfg.lr, foreach=True)
    buffer = ReplayBuffer(min(cfg.buffer_size, max(cfg.total_env_steps, cfg.batch_size)), env.obs_dim, device)
    gen = torch.Generator(device=device)
    gen.manual_seed(cfg.seed + 1)

    n = cfg.num_envs
    env_steps = updates = 0
    episodes: list[tuple] = []  # (episode, env_step, reward, steps, collisions, success)
    ep_reward = torch.zeros(n, device=device)
    ep_collisions = torch.zeros(n, dtype=torch.long, device=device)
    env.reset()
    if cfg.resume and (out / "last.pt").exists():
        state = torch.load(out / "last.pt", map_location=device, weights_only=False)
        q.load_state_dict(state["q"])
        q_target.load_state_dict(state["q_target"])
        optimizer.load_state_dict(state["optimizer"])
        if "replay" in state:
            buffer.load_state_dict(state["replay"])
        env_steps, updates, episodes = state["env_steps"], state["updates"], [tuple(e) for e in state["episodes"]]
        gen.set_state(state["gen"].cpu())
        env.gen.set_state(state["env_gen"].cpu())
        for k in env.state_keys:
            setattr(env, k, state["env"][k].to(device))
        ep_reward, ep_collisions = state["ep_reward"].to(device), state["ep_collisions"].to(device)
        if cfg.verbose:
            print(f"resumed from {out / 'last.pt'} at {env_steps} env steps, {updates} updates")

    def save_last():
        state = {"format": CHECKPOINT_FORMAT, "config": json.dumps(cfg.to_dict()), "q": q.state_dict(),
                 "q_target": q_target.state_dict(), "optimizer": optimizer.state_dict(),
                 "env_steps": env_steps, "updates": updates, "episodes": episodes,
                 "gen": gen.get_state(), "env_gen": env.gen.get_state(),
                 "env": {k: getattr(env, k) for k in env.state_keys},
                 "ep_reward": ep_reward, "ep_collisions": ep_collisions,
                 "normalizer": normalizer.to_dict()}
        if cfg.save_replay:
            state["replay"] = buffer.state_dict()
        torch.save(state, out / "last.pt")

    obs = env.observe()
    next_checkpoint = (env_steps // cfg.checkpoint_every + 1) * cfg.checkpoint_every if cfg.checkpoint_every else None
    next_log = env_steps + cfg.total_env_steps // 10
    while env_steps < cfg.total_env_steps and not (cfg.episodes and len(episodes) >= cfg.episodes):
        # 1. act epsilon-greedily
        eps = epsilon(cfg, env_steps)
        with torch.no_grad():
            greedy = q(obs).argmax(1)
        explore = torch.rand(n, generator=gen, device=device) < eps
        random_actions = torch.randint(4, (n,), generator=gen, device=device)
        actions = torch.where(explore, random_actions, greedy)

        # 2. step every robot, store the transitions (truncation is not termination: bootstrap through it)
        next_obs, reward, terminated, truncated, info = env.step(actions)
        buffer.add(obs, actions, reward, next_obs, terminated)
        env_steps += n

        # 3. book-keeping of finished episodes, then reset them
        ep_reward += reward
        ep_collisions += info["collision"].long()
        done = terminated | truncated
        if done.any():
            for i in torch.nonzero(done, as_tuple=True)[0].tolist():
                episodes.append((len(episodes), env_steps, float(ep_reward[i]), int(info["steps"][i]),
                                 int(ep_collisions[i]), bool(terminated[i])))
            ep_reward[done], ep_collisions[done] = 0.0, 0
            env.reset_where(done)
        obs = env.observe()

        # 4. gradient updates owed for the steps collected so far
        owed = (env_steps - cfg.learning_starts) // cfg.env_steps_per_update if env_steps >= cfg.learning_starts else 0
        while updates < owed:
            b_obs, b_act, b_rew, b_next, b_term = buffer.sample(cfg.batch_size, gen)
            with torch.no_grad():
                next_q = q_target(b_next)
                if cfg.double_dqn:
                    next_v = next_q.gather(1, q(b_next).argmax(1, keepdim=True)).squeeze(1)
                else:
                    next_v = next_q.max(1).values
                td_target = b_rew + cfg.gamma * (1.0 - b_term) * next_v
            q_sa = q(b_obs).gather(1, b_act[:, None]).squeeze(1)
            loss = F.smooth_l1_loss(q_sa, td_target)  # Huber
            if cfg.lr_end >= 0:
                for group in optimizer.param_groups:
                    group["lr"] = cfg.lr + min(1.0, env_steps / cfg.total_env_steps) * (cfg.lr_end - cfg.lr)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if cfg.max_grad_norm > 0:
                nn.utils.clip_grad_norm_(q.parameters(), cfg.max_grad_norm)
            optimizer.step()
            updates += 1
            if updates % cfg.target_update_every == 0:
                q_target.load_state_dict(q.state_dict())

        if next_checkpoint is not None and env_steps >= next_checkpoint:
            save_last()
            next_checkpoint += cfg.checkpoint_every
        if cfg.verbose and env_steps >= next_log:
            s = _summary(episodes)
            print(f"[{time.perf_counter() - t_start:6.1f}s] steps {env_steps:>8d}  updates {updates:>6d}  "
                  f"episodes {len(episodes):>6d}  eps {eps:.3f}  success {s.get('success_rate', 0):.3f}  "
                  f"collisions/ep {s.get('collisions', 0):.2f}")
            next_log += cfg.total_env_steps // 10

    wall = time.perf_counter() - t_start
    save_last()
    ckpt = out / "model.pt"
    save_checkpoint(ckpt, q, cfg, normalizer, env.obs_table.names, ds,
                    stats={"env_steps": env_steps, "updates": updates, "episodes": len(episodes), "wall_s": wall})
    write_curves(episodes, out)
    return TrainResult(ckpt, out, env_steps, updates, len(episodes), wall, _summary(episodes))


def _summary(episodes: list[tuple]) -> dict[str, float]:
    if not episodes:
        return {}
    tail = np.array([e[2:] for e in episodes[-max(1, len(episodes) // 10):]], dtype=np.float64)
    return {"reward": float(tail[:, 0].mean()), "steps": float(tail[:, 1].mean()),
            "collisions": float(tail[:, 2].mean()), "success_rate": float(tail[:, 3].mean())}


# -- checkpoints, configs, curves ----------------------------------------------------------------------------------
def write_config(cfg: DQNConfig, directory: Path) -> Path:
    path = Path(directory) / "config.json"
    path.write_text(json.dumps(cfg.to_dict(), indent=2) + "\n")
    return path


def save_checkpoint(path: Path, q: QNetwork, cfg: DQNConfig, normalizer: Normalizer, obs_names, ds: Dataset,
                    stats: dict[str, Any] | None = None) -> Path:
    """A self-contained policy: weights, architecture, config, observation preset and normaliser."""
    torch.save({"format": CHECKPOINT_FORMAT, "config": json.dumps(cfg.to_dict()),
                "arch": {"in_dim": len(obs_names), "hidden": list(cfg.hidden), "n_actions": 4},
                "obs": {"preset": cfg.obs, "names": list(obs_names)}, "normalizer": normalizer.to_dict(),
                "dataset": {"name": ds.name, "version": ds.version}, "stats": stats or {},
                "q": {k: v.detach().cpu() for k, v in q.state_dict().items()}}, path)
    write_config(cfg, Path(path).parent)
    return Path(path)


@dataclass
class Policy:
    """A trained greedy policy and everything needed to observe a twin the way it was trained."""

    q: QNetwork
    config: DQNConfig
    normalizer: Normalizer
    obs_preset: str
    meta: dict[str, Any]

    def act(self, obs: torch.Tensor, shield: bool = False) -> torch.Tensor:
        """Greedy actions. ``shield=True`` (``neighbors`` preset only) never picks a move into a neighbour that
        the twin shows without radio features (blocked or off the grid), unless every move is such."""
        with torch.no_grad():
            q = self.q(obs)
            if shield:
                flags = obs[..., self.shield_columns()] > 0.5
                q = torch.where(flags | ~flags.any(-1, keepdim=True), q, torch.full_like(q, -torch.inf))
            return q.argmax(-1)

    def shield_columns(self) -> list[int]:
        """Observation columns of the four has-radio flags (``neighbors`` preset), in action order."""
        if self.obs_preset != "neighbors":
            raise ConfigError(f"the obstacle shield needs the 'neighbors' observation preset, "
                              f"this policy observes {self.obs_preset!r}")
        from .observations import PAPER_COLUMNS, RADIO_FEATURES

        k = len(RADIO_FEATURES) + 1
        return [len(PAPER_COLUMNS) + a * k + k - 1 for a in range(4)]

    def env_for(self, ds: Dataset, num_envs: int, **kwargs) -> BatchedNavEnv:
        """A batched env over ``ds`` that observes with this policy's preset and training normaliser."""
        return BatchedNavEnv.from_dataset(ds, num_envs, obs=self.obs_preset, normalizer=self.normalizer, **kwargs)

    def observations(self, ds: Dataset):
        return build_observations(ds, self.obs_preset, self.normalizer)


def load_policy(path: str | Path, device: str = "cpu") -> Policy:
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"no checkpoint at {path}", hint="train one first, e.g. `make train SCENE=cubicle`")
    state = torch.load(path, map_location=device, weights_only=False)
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT or "arch" not in state:
        raise CheckpointError(f"{path} is not a dtradar DQN checkpoint (model.pt)",
                              hint="pass the model.pt written by `python -m dtradar_rl train`")
    arch = state["arch"]
    q = QNetwork(arch["in_dim"], tuple(arch["hidden"]), arch["n_actions"]).to(device)
    q.load_state_dict(state["q"])
    q.eval()
    cfg = DQNConfig.from_dict(json.loads(state["config"]))
    return Policy(q, cfg, Normalizer.from_dict(state["normalizer"]), state["obs"]["preset"],
                  {"dataset": state["dataset"], "stats": state["stats"], "path": str(path)})


def write_curves(episodes: list[tuple], out: Path) -> tuple[Path, Path]:
    """``curves.csv`` (one row per episode) and ``curves.png`` (reward, steps, collisions; moving averages)."""
    csv_path, png_path = out / "curves.csv", out / "curves.png"
    with csv_path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["episode", "env_step", "reward", "steps", "collisions", "success"])
        w.writerows(episodes)
    from .plots import plot_curves

    plot_curves(episodes, png_path)
    return csv_path, png_path


__all__ = ["DQNConfig", "PRESETS", "config_for", "train", "TrainResult", "QNetwork", "ReplayBuffer", "Policy",
           "load_policy", "save_checkpoint", "epsilon"]
