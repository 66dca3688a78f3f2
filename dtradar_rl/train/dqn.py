"""Deep Q-learning on a dataset's navigation MDP, readable top to bottom (after CleanRL's ``dqn.py``).

    from dtradar_rl.train import config_for, train
    result = train(config_for("tuned", scene="synthetic", total_env_steps=100_000))
    result.checkpoint   # runs/synthetic/dqn/model.pt, with config.json, curves.csv and curves.png beside it

Seven presets (:data:`~dtradar_rl.train.config.PRESETS`, :func:`~dtradar_rl.train.config.config_for`; the default is
:data:`~dtradar_rl.train.config.DEFAULT_PRESET`); what each reaches is measured in the docs (Navigation,
Benchmarks), not here:

``paper``  the paper's protocol: its Table VI start/target pair per run (:mod:`dtradar_rl.task.pairs`), ``paper``
           observations (10 inputs, no target) and reward, 5 dense ReLU layers of 256, γ = 0.9, constant ε = 0.1,
           one environment, one gradient update per step, episodes until the target (safety cap 10x the shortest
           path), 500 episodes indoor / 80 outdoor.
``tuned``  goal-conditioned over random pairs (the base the other presets but ``paper`` extend): ``neighbors``
           observations (senses blocked neighbours), ``geodesic`` shaped reward, Double DQN, 2 x 256 hidden units,
           γ = 0.5, 256 robots in the batched torch environment, ε decaying 1 → 0.05 over 40 % of the budget, Adam
           1e-3 decaying linearly to 1e-4, one gradient update (batch 512) per 48 environment steps: updates, not
           table lookups, bound the speed.
``robust`` ``tuned`` + obstacle augmentation (domain randomisation, :mod:`dtradar_rl.envs.batched`): at every episode
           reset each robot gets 10 random extra obstacles of 1 x 1 to 2 x 2 cells that collide and read as blocked
           neighbours, with the geodesic potential replanned around them, so the agent learns to detour.
``memory`` ``robust`` + a window of the obstacles sensed and cells visited so far (:mod:`dtradar_rl.envs.memory`), so a
           dead end, once seen, is not revisited.
``memory-escape`` ``memory`` + the count of the robot's earlier stands on its cell (``visits_here``)
           in its observation, and a loop escape when acting: a robot back on a cell for the third time takes a
           random move (:class:`~dtradar_rl.agents.policy.Policy`), so a deterministic cycle cannot last until the
           step limit.
``memory-escape-noise`` ``memory-escape`` trained on noisy radio features
           (:mod:`dtradar_rl.task.noise`, ``realistic``): as good as ``memory-escape`` without noise on every twin
           measured, and it keeps its path lengths under a receiver's measurement errors.
``memory-escape-noise-margin`` (the default) ``memory-escape-noise`` with DQfD's large-margin loss towards the
           training twin's breadth-first shortest moves (``expert_weight`` 1, :func:`expert_margin_loss`): told the
           shortest way in the states it visits, it learns shorter paths in the same budget.

The loop: every robot acts ε-greedily, the batch of transitions goes into a replay buffer, finished robots are
reset; every ``env_steps_per_update`` environment steps one Huber-loss update on a random minibatch follows, with
targets from a target network copied every ``target_update_every`` updates; with ``expert_weight`` > 0, DQfD's
large-margin loss towards the twin's breadth-first shortest moves is added to it (:func:`expert_margin_loss`; what
:mod:`dtradar_rl.experiments.adapt` fine-tunes with). Checkpoints carry the config and the
feature normaliser; ``last.pt`` also carries optimiser, replay buffer and random states, so ``resume=True``
continues a run exactly where it stopped.

:func:`train` reads as these steps, each a function below it in that order: the set-up (:func:`_set_up`: the twin,
the env, the networks, a resumed state), the loop (:func:`_training_loop`: :func:`_act`, :func:`_step`,
:func:`_update`, then :func:`_checkpoint_and_log`) and the final saves (:func:`_finish`). What they share is a
:class:`~dtradar_rl.train.run_state.RunState`, which is also what ``last.pt`` saves and a resumed run restores.
"""

from __future__ import annotations

import copy
import csv
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_rl.agents.checkpoints import save_checkpoint, twin_record, write_config
from dtradar_rl.agents.policy import QNetwork
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.memory import batched_env
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.pairs import ResolvedPair, training_pair
from dtradar_rl.task.runs import held_out_folder
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DQNConfig, with_budget
from dtradar_rl.train.replay import ReplayBuffer
from dtradar_rl.train.run_state import RunState, restore_training_state, save_training_state
from dtradar_rl.train.saved_runs import check_resumed_twin, check_run_folder
from dtradar_rl.viz.plots import plot_curves


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


def epsilon(cfg: DQNConfig, env_steps: int) -> float:
    """Linear decay from ``eps_start`` to ``eps_end`` over ``eps_decay_fraction`` of the budget."""
    span = cfg.eps_decay_fraction * cfg.total_env_steps
    frac = 1.0 if span <= 0 else min(1.0, env_steps / span)
    return cfg.eps_start + frac * (cfg.eps_end - cfg.eps_start)


def train(
    config: DQNConfig,
    dataset: Dataset | None = None,
    *,
    init: dict[str, Any] | None = None,
    normalizer: Normalizer | None = None,
    callback: Callable[..., bool] | None = None,
) -> TrainResult:
    """Train a DQN agent on ``dataset`` (default: load ``config.dataset_name``); write checkpoints and curves.

    Fine-tuning (:mod:`dtradar_rl.experiments.adapt`): ``init`` is a Q-network state dict to start from and
    ``normalizer`` the one it was trained with; ``callback(q, env_steps, train_s)`` runs after every batch of steps with
    the seconds spent in the training loop (set-up excluded), its own time is not counted there or in ``wall_s``, and it
    stops training by returning True."""
    cfg = config.validate()
    t_start = time.perf_counter()
    # One run per folder, for the whole run: a second one would interleave its checkpoints and curves with these.
    with held_out_folder(cfg.out_dir, f"training {cfg.scene}/{cfg.variant} ({cfg.preset})", what="training run"):
        run = _set_up(cfg, dataset, init, normalizer)
        callback_s = _training_loop(run, callback, t_start)
        wall = time.perf_counter() - t_start - callback_s
        return _finish(run, wall)


# -- set-up ----------------------------------------------------------------------------------------------------------
def _set_up(
    cfg: DQNConfig, dataset: Dataset | None, init: dict[str, Any] | None, normalizer: Normalizer | None
) -> RunState:
    """Everything before the first step: torch's threads and seed, the run folder's checks, the twin, the env, the
    networks, the optimiser and the buffer, every robot reset; a resumed run's state; then ``config.json``."""
    torch.set_num_threads(cfg.threads or auto_threads())
    torch.set_flush_denormal(True)  # tiny Adam moments otherwise slow every CPU update down several-fold
    torch.manual_seed(cfg.seed)
    device = torch.device(cfg.device)
    out = cfg.out_dir
    # A run folder belongs to one scene and one config family: refused here, before anything loads or is written.
    resumed = check_run_folder(cfg, out)
    ds = dataset if dataset is not None else load_dataset(cfg.dataset_name)
    if resumed is not None:
        check_resumed_twin(resumed, ds, out)
    threads = {"threads": torch.get_num_threads(), "threads_setting": cfg.threads}
    normalizer = normalizer or Normalizer.fit(ds)
    pair = training_pair(cfg, ds)
    env = _make_env(cfg, ds, normalizer, pair, device)
    # The default budget (0) grows with the twin's free cells (the static map's on a moving twin); from here on the
    # run, its checkpoints and config.json hold the steps it was given.
    cfg = with_budget(cfg, int(env.mdp.free.sum()), moving=ds.is_moving)
    q = QNetwork(env.obs_dim, cfg.hidden, env.num_actions).to(device)
    if init is not None:
        q.load_state_dict(init)
    q_target = copy.deepcopy(q)
    optimizer = torch.optim.Adam(q.parameters(), lr=cfg.lr, foreach=True)
    buffer = ReplayBuffer(min(cfg.buffer_size, max(cfg.total_env_steps, cfg.batch_size)), env.obs_dim, device)
    gen = torch.Generator(device=device)
    gen.manual_seed(cfg.seed + 1)
    n = cfg.num_envs
    run = RunState(
        cfg=cfg,
        out=out,
        ds=ds,
        normalizer=normalizer,
        pair=pair,
        env=env,
        q=q,
        q_target=q_target,
        optimizer=optimizer,
        buffer=buffer,
        gen=gen,
        threads=threads,
        device=device,
        ep_reward=torch.zeros(n, device=device),
        ep_collisions=torch.zeros(n, dtype=torch.long, device=device),
    )
    run.reset_where(torch.ones(n, dtype=torch.bool, device=device))
    if pair and cfg.verbose:
        print(
            f"pair ({pair.source}): start {pair.start} -> target {pair.target}, shortest {pair.shortest} steps, "
            f"episode cap {env.max_steps}"
        )
    if resumed is not None:
        restore_training_state(run, resumed)
    # Only now, every check passed and the state loaded: a refused or failed start leaves the folder as it was.
    write_config(cfg, out)
    return run


def _make_env(
    cfg: DQNConfig, ds: Dataset, normalizer: Normalizer, pair: ResolvedPair | None, device: torch.device
) -> BatchedNavEnv:
    """The batched environment of ``cfg`` on ``ds`` (the memory env when the config has memory)."""
    return batched_env(
        ds,
        cfg.num_envs,
        memory_radius=cfg.memory_radius,
        memory_bumps=cfg.memory_bumps,
        memory_visits=cfg.memory_visits,
        obs=cfg.obs,
        sense_radius=cfg.sense_radius,
        clock=cfg.clock,
        wait_action=cfg.wait_action,
        mover_penalty=cfg.mover_penalty,
        normalizer=normalizer,
        reward=cfg.reward,
        max_steps=cfg.max_steps or (pair.cap if pair else None),
        device=device,
        seed=cfg.seed,
        aug_obstacles=cfg.aug_obstacles,
        aug_obstacle_size=cfg.aug_obstacle_size,
        aug_potential=cfg.aug_potential,
        noise=cfg.noise,
    )


# -- the loop --------------------------------------------------------------------------------------------------------
def _training_loop(run: RunState, callback: Callable[..., bool] | None, t_start: float) -> float:
    """Act, step, update, then the callback, checkpoints and progress, until the step budget (or the episode budget)
    is spent or the callback stops it; returns the seconds the callback took."""
    cfg = run.cfg
    obs = run.env.observe()
    t_loop = time.perf_counter()  # the callback's clock starts here: loading and env tables are set-up, not training
    callback_s = 0.0
    schedule = _Schedule.after(cfg, run.env_steps)
    while run.env_steps < cfg.total_env_steps and not (cfg.episodes and len(run.episodes) >= cfg.episodes):
        eps = epsilon(cfg, run.env_steps)
        actions = _act(run, obs, eps)
        obs = _step(run, obs, actions)
        _update(run)
        if callback is not None:
            t_cb = time.perf_counter()
            stop = callback(run.q, run.env_steps, t_cb - t_loop - callback_s)
            callback_s += time.perf_counter() - t_cb
            if stop:
                break
        _checkpoint_and_log(run, schedule, eps, t_start)
    return callback_s


def _act(run: RunState, obs: torch.Tensor, eps: float) -> torch.Tensor:
    """Every robot's action, epsilon-greedy on the Q-network."""
    n, device = run.cfg.num_envs, run.device
    with torch.no_grad():
        greedy = run.q(obs).argmax(1)
    explore = torch.rand(n, generator=run.gen, device=device) < eps
    random_actions = torch.randint(run.env.num_actions, (n,), generator=run.gen, device=device)
    return torch.where(explore, random_actions, greedy)


def _step(run: RunState, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """Step every robot and store the transitions (truncation is not termination: bootstrap through it); record the
    finished episodes and reset them. Returns the next observations."""
    env = run.env
    expert = env.shortest_moves() if run.cfg.expert_weight > 0 else None
    next_obs, reward, terminated, truncated, info = env.step(actions)
    run.buffer.add(obs, actions, reward, next_obs, terminated, expert)
    run.env_steps += run.cfg.num_envs
    run.ep_reward += reward
    run.ep_collisions += info["collision"].long()
    done = terminated | truncated
    if done.any():
        for i in torch.nonzero(done, as_tuple=True)[0].tolist():
            run.episodes.append(
                (
                    len(run.episodes),
                    run.env_steps,
                    float(run.ep_reward[i]),
                    int(info["steps"][i]),
                    int(run.ep_collisions[i]),
                    bool(terminated[i]),
                )
            )
        run.ep_reward[done], run.ep_collisions[done] = 0.0, 0
        run.reset_where(done)
    return env.observe()


def _update(run: RunState) -> None:
    """The gradient updates owed for the steps collected so far: one Huber-loss (Double) DQN update on a random
    minibatch each, DQfD's margin loss added with ``expert_weight`` > 0, the target network copied every
    ``target_update_every`` updates."""
    cfg, q, optimizer = run.cfg, run.q, run.optimizer
    owed = (
        (run.env_steps - cfg.learning_starts) // cfg.env_steps_per_update if run.env_steps >= cfg.learning_starts else 0
    )
    while run.updates < owed:
        b_obs, b_act, b_rew, b_next, b_term, b_expert = run.buffer.sample(cfg.batch_size, run.gen)
        with torch.no_grad():
            next_q = run.q_target(b_next)
            if cfg.double_dqn:
                next_v = next_q.gather(1, q(b_next).argmax(1, keepdim=True)).squeeze(1)
            else:
                next_v = next_q.max(1).values
            td_target = b_rew + cfg.gamma * (1.0 - b_term) * next_v
        q_all = q(b_obs)
        q_sa = q_all.gather(1, b_act[:, None]).squeeze(1)
        loss = F.smooth_l1_loss(q_sa, td_target)  # Huber
        if cfg.expert_weight > 0:
            loss = loss + cfg.expert_weight * expert_margin_loss(q_all, b_expert, cfg.expert_margin)
        if cfg.lr_end >= 0:
            for group in optimizer.param_groups:
                group["lr"] = cfg.lr + min(1.0, run.env_steps / cfg.total_env_steps) * (cfg.lr_end - cfg.lr)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.max_grad_norm > 0:
            nn.utils.clip_grad_norm_(q.parameters(), cfg.max_grad_norm)
        optimizer.step()
        run.updates += 1
        if run.updates % cfg.target_update_every == 0:
            run.q_target.load_state_dict(q.state_dict())


# -- checkpoints and progress ----------------------------------------------------------------------------------------
@dataclass
class _Schedule:
    """When the loop next saves ``last.pt`` (None: never) and next prints its progress."""

    next_checkpoint: int | None
    next_log: int
    #: With an episode budget (the paper's protocol) the step backstop says nothing about progress: log by episodes.
    log_every_ep: int
    next_log_ep: int
    #: the env steps the loop started at (a resumed run's), for the rate and the time left
    start_steps: int = 0

    @classmethod
    def after(cls, cfg: DQNConfig, env_steps: int) -> _Schedule:
        """The schedule of a loop that starts at ``env_steps`` (0, or where a resumed run stopped)."""
        every = cfg.checkpoint_every
        log_every_ep = max(1, cfg.episodes // 25) if cfg.episodes else 0
        return cls(
            next_checkpoint=(env_steps // every + 1) * every if every else None,
            next_log=env_steps + cfg.total_env_steps // 10,
            log_every_ep=log_every_ep,
            next_log_ep=log_every_ep,
            start_steps=env_steps,
        )


def _checkpoint_and_log(run: RunState, schedule: _Schedule, eps: float, t_start: float) -> None:
    """Save ``last.pt`` and print the progress when the schedule says so."""
    cfg = run.cfg
    if schedule.next_checkpoint is not None and run.env_steps >= schedule.next_checkpoint:
        save_training_state(run)
        schedule.next_checkpoint += cfg.checkpoint_every
    log_due = len(run.episodes) >= schedule.next_log_ep if schedule.log_every_ep else run.env_steps >= schedule.next_log
    if cfg.verbose and log_due:
        s = _summary(run.episodes)
        elapsed = time.perf_counter() - t_start
        print(
            f"[{elapsed:6.1f}s] steps {run.env_steps:>8d}/{cfg.total_env_steps} "
            f"({100 * run.env_steps / max(1, cfg.total_env_steps):3.0f} %, {_rate_and_left(run, schedule, elapsed)})  "
            f"updates {run.updates:>6d}  episodes {len(run.episodes):>6d}  eps {eps:.3f}  "
            f"success {s.get('success_rate', 0):.3f}  collisions/ep {s.get('collisions', 0):.2f}"
        )
        schedule.next_log += cfg.total_env_steps // 10
        schedule.next_log_ep += schedule.log_every_ep


def _rate_and_left(run: RunState, schedule: _Schedule, elapsed: float) -> str:
    """``"2 345 steps/s, ~3.1 min left"`` (``~40 s left`` under a minute and a half): this loop's rate so far and the
    time left to the step budget at it (an episode budget, the paper's protocol, may end sooner)."""
    done = run.env_steps - schedule.start_steps
    if elapsed <= 0 or done <= 0:
        return "rate unknown yet"
    rate = done / elapsed
    left = max(0, run.cfg.total_env_steps - run.env_steps) / rate
    left_text = f"~{left:.0f} s left" if left < 90 else f"~{left / 60:.1f} min left"  # a short run: seconds
    return f"{rate:,.0f}".replace(",", " ") + f" steps/s, {left_text}"


# -- the end ---------------------------------------------------------------------------------------------------------
def _finish(run: RunState, wall: float) -> TrainResult:
    """The final saves: ``last.pt``, the policy checkpoint ``model.pt``, the curves and ``run.json``."""
    save_training_state(run)
    out, env, pair = run.out, run.env, run.pair
    ckpt = out / "model.pt"
    stats = {
        "env_steps": run.env_steps,
        "updates": run.updates,
        "episodes": len(run.episodes),
        "wall_s": wall,
        **run.threads,
        **({"pair": pair.to_dict()} if pair else {}),
    }
    obs_names = getattr(env, "obs_names", env.obs_table.names)
    save_checkpoint(ckpt, run.q, run.cfg, run.normalizer, obs_names, run.ds, stats=stats)
    write_curves(run.episodes, out)
    write_run_record(out, run.ds, stats)
    return TrainResult(ckpt, out, run.env_steps, run.updates, len(run.episodes), wall, _summary(run.episodes))


def write_run_record(out: Path, ds: Dataset, stats: dict[str, Any]) -> Path:
    """``run.json``: how the run went and on what (the twin, steps, seconds, the torch threads it used and the
    ``--threads`` setting, torch's version), beside ``config.json`` (which stays the config alone)."""
    record = {"dataset": twin_record(ds), "stats": stats, "torch": torch.__version__}
    path = out / "run.json"
    write_atomic(path, json.dumps(record, indent=2, default=str) + "\n")
    return path


def expert_margin_loss(q_all: torch.Tensor, expert: torch.Tensor, margin: float) -> torch.Tensor:
    """DQfD's large-margin loss (Hester et al. 2018), with a set of expert moves per state:
    ``max_a [Q(s, a) + margin * (a not expert)] - max_(a expert) Q(s, a)``, averaged over states with an expert move.
    Zero once every expert move's value leads every other move's by ``margin``; TD learning still sets the values.
    ``expert`` may have fewer columns than ``q_all``: the wait action (``--wait-action``'s fifth) never brings a robot
    closer along a breadth-first path, so it is never an expert move and must trail the expert's by the margin."""
    if expert.shape[1] < q_all.shape[1]:
        pad = expert.new_zeros((expert.shape[0], q_all.shape[1] - expert.shape[1]))
        expert = torch.cat([expert, pad], dim=1)
    has = expert.any(1)
    if not bool(has.any()):
        return q_all.sum() * 0.0
    q, e = q_all[has], expert[has]
    best_expert = q.masked_fill(~e, float("-inf")).max(1).values
    return ((q + margin * (~e).float()).max(1).values - best_expert).mean()


def _summary(episodes: list[tuple]) -> dict[str, float]:
    if not episodes:
        return {}
    tail = np.array([e[2:] for e in episodes[-max(1, len(episodes) // 10) :]], dtype=np.float64)
    return {
        "reward": float(tail[:, 0].mean()),
        "steps": float(tail[:, 1].mean()),
        "collisions": float(tail[:, 2].mean()),
        "success_rate": float(tail[:, 3].mean()),
    }


# -- curves ----------------------------------------------------------------------------------------------------------
def write_curves(episodes: list[tuple], out: Path) -> tuple[Path, Path]:
    """``curves.csv`` (one row per episode) and ``curves.png`` (reward, steps, collisions; moving averages)."""
    csv_path, png_path = out / "curves.csv", out / "curves.png"
    with open_atomic(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["episode", "env_step", "reward", "steps", "collisions", "success"])
        w.writerows(episodes)
    plot_curves(episodes, png_path)
    return csv_path, png_path


__all__ = ["TrainResult", "epsilon", "expert_margin_loss", "train"]
