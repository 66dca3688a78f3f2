"""Evaluation of a trained policy on a twin: success, SPL, collisions, steps, decision latency; paths and tables.

Metrics over a set of seeded (start, target) pairs, drawn among connected free cells *of the twin evaluated*:

* ``success_rate``: fraction of episodes that reach the target within the step limit;
* ``spl``: Success weighted by Path Length (Anderson et al. 2018), ``mean_i S_i · l_i / max(p_i, l_i)``, with
  ``l_i`` the breadth-first shortest path on the evaluated twin and ``p_i`` the length of the path travelled
  (moves between cells; a collision does not move the robot, so it is counted in ``collisions`` instead);
* ``collisions``: mean collisions per episode; ``steps``: mean decisions per episode (collisions included);
* ``latency_ms``: median wall time of one greedy decision for one robot (table lookup + network), batch size 1.

On a moving twin (:mod:`dtradar_rl.task.grid_mdp`) an episode is ``(start, target, t0)``: the pairs of
:func:`sample_eval_pairs` carry a third column, the start snapshot (uniform among those in which the start is free,
redrawn until the target can be reached in time). There

* ``spl`` compares *time*: ``l_i`` is the space-time shortest path (the fewest steps from the start at ``t0``,
  waiting allowed; :meth:`~dtradar_rl.task.grid_mdp.MovingGridMDP.space_time_distances_many`) and ``p_i`` the steps
  the episode took (waits and bumps included: each step is one snapshot of time);
* ``collisions`` counts every move that failed (into a wall or a mover), ``wall_collisions`` and
  ``mover_collisions`` split it, and ``mover_hits`` counts the movers that walked onto the robot (per episode).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.policy import Policy
from dtradar_rl.task.grid_mdp import GridMDP, MovingGridMDP
from dtradar_rl.task.noise import noise_model
from dtradar_rl.task.runtime import DECISION_THREADS, torch_threads
from dtradar_rl.task.twins import load_dataset

#: Decisions timed for the latency figures (after a warm-up of LATENCY_WARMUP untimed ones).
LATENCY_DECISIONS = 1000
LATENCY_WARMUP = 50

#: The headline metrics every summary over seeds reports (sweeps, the offline benchmark).
METRICS: tuple[str, ...] = ("success_rate", "spl", "collisions")


@dataclass
class Rollouts:
    """Greedy episodes: per pair the visited cells, success, decisions, collisions, and the shortest length."""

    pairs: np.ndarray  # int64[N, 2] (start, target) cells
    paths: list[list[int]]  # visited cells, start first (repeated cells where a collision happened)
    success: np.ndarray  # bool[N]
    steps: np.ndarray  # int64[N] decisions taken
    collisions: np.ndarray  # int64[N]
    shortest: np.ndarray  # int64[N] BFS shortest path length on the evaluated twin (moving: space-time, in steps)
    #: moving twins only (else None): start snapshots and, per episode, wall collisions, mover collisions, mover hits
    t0: np.ndarray | None = None
    wall_collisions: np.ndarray | None = None
    mover_collisions: np.ndarray | None = None
    mover_hits: np.ndarray | None = None


@dataclass
class Metrics:
    pairs: int
    success_rate: float
    spl: float
    collisions: float
    steps: float
    path_length: float
    shortest: float
    #: one robot's greedy decision, ms: median (p50) and 99th percentile over LATENCY_DECISIONS decisions
    latency_ms: float | None = None
    latency_p99_ms: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: moving twins only (per episode; left out of :meth:`to_dict` on a static twin)
    wall_collisions: float | None = None
    mover_collisions: float | None = None
    mover_hits: float | None = None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if self.mover_hits is None:
            for key in MOVING_METRICS:
                d.pop(key)
        return d


#: The metrics of a moving twin that a static one does not have.
MOVING_METRICS: tuple[str, ...] = ("wall_collisions", "mover_collisions", "mover_hits")


def path_length(path: Sequence[int]) -> int:
    """Moves between distinct consecutive cells (collisions, which repeat a cell, travel nothing)."""
    p = np.asarray(path)
    return int((p[1:] != p[:-1]).sum()) if p.size > 1 else 0


def spl(success: Sequence[bool], shortest: Sequence[int], travelled: Sequence[int]) -> float:
    """Success weighted by (normalised inverse) Path Length; 1.0 means every episode took a shortest path."""
    s = np.asarray(success, np.float64)
    lo = np.asarray(shortest, np.float64)
    p = np.asarray(travelled, np.float64)
    if s.size == 0:
        return float("nan")
    ratio = np.where(np.maximum(p, lo) > 0, lo / np.maximum(np.maximum(p, lo), 1e-12), 1.0)
    return float((s * ratio).mean())


def metrics_from_rollouts(r: Rollouts, latency_ms: tuple[float, float] | None = None) -> Metrics:
    """The metrics of ``r``; ``latency_ms`` is the (p50, p99) of :func:`decision_latency_ms`, if measured."""
    travelled = np.array([path_length(p) for p in r.paths])
    moving = r.t0 is not None
    moving_means = {key: float(getattr(r, key).mean()) for key in MOVING_METRICS} if moving else {}
    return Metrics(
        pairs=len(r.paths),
        success_rate=float(r.success.mean()),
        # on a moving twin the shortest length is in steps (time), so the travelled one is too
        spl=spl(r.success, r.shortest, r.steps if moving else travelled),
        collisions=float(r.collisions.mean()),
        steps=float(r.steps.mean()),
        path_length=float(travelled.mean()),
        shortest=float(r.shortest.mean()),
        latency_ms=None if latency_ms is None else latency_ms[0],
        latency_p99_ms=None if latency_ms is None else latency_ms[1],
        **moving_means,
    )


def sample_eval_pairs(ds: Dataset, n: int, seed: int) -> np.ndarray:
    """``n`` seeded connected (start, target) pairs on ``ds`` (the same pairs for the same twin and seed); on a
    moving twin ``int64[n, 3]`` (start, target, t0) episodes that the movers leave reachable."""
    mdp = GridMDP.from_dataset(ds)
    if isinstance(mdp, MovingGridMDP):
        return mdp.sample_episodes(n, np.random.default_rng(seed))
    return mdp.sample_pairs(n, np.random.default_rng(seed))


def rollout(
    policy: Policy,
    ds: Dataset,
    pairs: np.ndarray,
    *,
    max_steps: int | None = None,
    device: str = "cpu",
    shield: bool = False,
    noise: str = "none",
    noise_seed: int = 0,
) -> Rollouts:
    """Run the greedy policy from every (start, target) pair at once in the batched environment.

    ``shield``: mask moves into neighbours sensed as occupied (see :meth:`Policy.act`). ``noise``: the robots
    observe the radio features as a receiver would measure them (:mod:`dtradar_rl.task.noise`), seeded by
    ``noise_seed``. On a moving twin ``pairs`` may carry a third column, the start snapshot ``t0``
    (:func:`sample_eval_pairs`); without it each episode starts in the first snapshot in which its start is free."""
    pairs = np.asarray(pairs, np.int64)
    pairs = pairs.reshape(-1, 3 if pairs.ndim == 2 and pairs.shape[1] == 3 else 2)
    n = len(pairs)
    kw = {} if noise_model(noise).is_zero else {"noise": noise, "seed": noise_seed}
    env = policy.env_for(ds, n, reward="paper", max_steps=max_steps or None, device=device, **kw)
    moving = isinstance(env.mdp, MovingGridMDP)
    t0 = pairs[:, 2] if pairs.shape[1] == 3 else None
    if moving and t0 is None:  # the first snapshot in which each start is free
        t0 = (~env.mdp.covered[:, pairs[:, 0]]).argmax(0)
    env.reset_where(
        torch.ones(n, dtype=torch.bool), starts=pairs[:, 0], targets=pairs[:, 1], **({} if t0 is None else {"t0": t0})
    )
    cells = [env.cell.clone()]
    done = torch.zeros(n, dtype=torch.bool, device=env.device)
    success = torch.zeros_like(done)
    steps = torch.zeros(n, dtype=torch.long, device=env.device)
    collisions = torch.zeros_like(steps)
    if moving:
        mover_collisions, mover_hits = torch.zeros_like(steps), torch.zeros_like(steps)
    while not bool(done.all()):
        actions = policy.act(env.observe(), shield=shield)
        _, _, terminated, truncated, info = env.step(actions)
        active = ~done
        steps += active.long()
        collisions += (info["collision"] & active).long()
        if moving:
            mover_collisions += (info["mover_collision"] & active).long()
            mover_hits += (info["mover_hit"] & active).long()
        success |= terminated & active
        done |= terminated | truncated
        cells.append(env.cell.clone())
    trace = torch.stack(cells, 1).cpu().numpy()  # [N, T+1]
    steps_np = steps.cpu().numpy()
    paths = [trace[i, : steps_np[i] + 1].tolist() for i in range(n)]
    mdp = env.mdp
    targets, inverse = np.unique(pairs[:, 1], return_inverse=True)
    if not moving:
        dist = mdp.bfs_distances_many(targets)
        shortest = dist[inverse, pairs[:, 0]]
        return Rollouts(pairs, paths, success.cpu().numpy(), steps_np, collisions.cpu().numpy(), shortest)
    shortest = mdp.space_time_distances_many(targets)[inverse, t0, pairs[:, 0]].astype(np.int64)
    col, mc = collisions.cpu().numpy(), mover_collisions.cpu().numpy()
    return Rollouts(
        pairs,
        paths,
        success.cpu().numpy(),
        steps_np,
        col,
        shortest,
        t0=np.asarray(t0, np.int64),
        wall_collisions=col - mc,
        mover_collisions=mc,
        mover_hits=mover_hits.cpu().numpy(),
    )


def decision_latency_ms(
    policy: Policy, ds: Dataset, repeats: int = LATENCY_DECISIONS, threads: int = DECISION_THREADS
) -> tuple[float, float]:
    """p50 and p99 (ms) of one greedy decision for one robot (observation lookup + forward pass + argmax) over
    ``repeats`` decisions after a short warm-up, with ``threads`` torch threads (batch-1 decisions run
    single-threaded by default: steadier and as fast, see :data:`~dtradar_rl.task.runtime.DECISION_THREADS`)."""
    # the policy's own env, so memory agents and the planner observe as they act; no shaped reward (its table of
    # breadth-first distances took minutes to build on Munich, and a decision never reads it)
    env = policy.env_for(ds, 1, reward="paper")
    env.reset()
    times = np.empty(repeats)
    with torch_threads(threads):
        for i in range(-LATENCY_WARMUP, repeats):
            t0 = time.perf_counter()
            action = policy.act(env.observe())
            dt = time.perf_counter() - t0
            if i >= 0:
                times[i] = dt
            _, _, terminated, truncated, _ = env.step(action)
            env.reset_where(terminated | truncated)
    p50, p99 = np.percentile(times, [50, 99]) * 1e3
    return float(p50), float(p99)


def evaluate(
    policy: Policy,
    ds: Dataset,
    *,
    pairs: int = 500,
    seed: int = 2024,
    max_steps: int | None = None,
    latency: bool = True,
    device: str = "cpu",
    shield: bool = False,
    noise: str = "none",
) -> tuple[Metrics, Rollouts]:
    """Metrics of ``policy`` on ``ds`` over ``pairs`` seeded (start, target) pairs (``noise``: see :func:`rollout`,
    seeded by ``seed``)."""
    r = rollout(
        policy,
        ds,
        sample_eval_pairs(ds, pairs, seed),
        max_steps=max_steps,
        device=device,
        shield=shield,
        noise=noise,
        noise_seed=seed,
    )
    return metrics_from_rollouts(r, decision_latency_ms(policy, ds) if latency else None), r


def evaluate_twins(
    policy: Policy,
    scene: str,
    variants: Sequence[str],
    *,
    label: str = "",
    pairs: int = 500,
    seed: int = 2024,
    max_steps: int | None = None,
    device: str = "cpu",
    shield: bool = True,
    datasets: dict[str, Dataset] | None = None,
    noise: str = "none",
    latency: bool = True,
) -> list[tuple[dict[str, Any], Dataset, Rollouts]]:
    """:func:`evaluate` on every twin ``<scene>/<variant>`` that is built (others are skipped with a message),
    unshielded and, with ``shield`` and the neighbors preset, shielded. Returns ``(row, dataset, rollouts)`` per
    case; a row is ``{"case": "<label><trained> -> <twin>[ (shielded)]", "dataset", "version", "shield",
    **Metrics.to_dict()}``. ``datasets`` holds twins already loaded, by name; ``latency=False`` leaves the decision
    latency out (``None``)."""
    datasets = datasets or {}
    trained = policy.meta["dataset"]["name"]
    out = []
    for variant in variants:
        name = f"{scene}/{variant}"
        try:
            ds = datasets.get(name) or load_dataset(name)
        except DatasetNotFoundError as e:
            print(f"skipping {name}: {e}")  # the message and its fix (the build command)
            continue
        for sh in [False] + ([True] if shield and policy.obs_preset == "neighbors" else []):
            metrics, roll = evaluate(
                policy,
                ds,
                pairs=pairs,
                seed=seed,
                max_steps=max_steps,
                device=device,
                shield=sh,
                noise=noise,
                latency=latency,
            )
            noisy = "" if noise_model(noise).is_zero else f", noise {noise}"
            case = f"{label}{trained} -> {ds.name}" + (
                f" (shielded{noisy})" if sh else (f" ({noisy[2:]})" if noisy else "")
            )
            row = {"case": case, "dataset": ds.name, "version": ds.version, "shield": sh, "noise": noise}
            row["sensing"] = sensing_of(policy)
            out.append(({**row, **metrics.to_dict()}, ds, roll))
    return out


def sensing_of(policy) -> str:
    """The sensing a policy acts from (:mod:`dtradar_rl.task.sensing`), as every results table names it: an honest
    agent's own, and ``privileged`` for the learnt agents, whose observation presets hold the robot's ``x, y``
    (``privileged (paper)`` for the paper's own state)."""
    sensing = policy.meta.get("sensing")
    if sensing:
        return str(sensing)
    return "privileged (paper)" if getattr(policy, "obs_preset", "") == "paper" else "privileged"


# -- reports ------------------------------------------------------------------------------------------------------
COLUMNS = (
    ("sensing", "sensing", "{}"),
    ("pairs", "pairs", "{:d}"),
    ("success_rate", "success", "{:.3f}"),
    ("spl", "SPL", "{:.3f}"),
    ("collisions", "collisions/ep", "{:.2f}"),
    ("steps", "mean steps", "{:.1f}"),
    ("shortest", "mean shortest", "{:.1f}"),
    ("latency_ms", "decision p50 (ms)", "{:.3f}"),
    ("latency_p99_ms", "p99 (ms)", "{:.3f}"),
)
#: The column added after SPL when the rows carry their normalised score (dtradar_rl.evaluation.scored_rows).
NORMALIZED_COLUMN = ("normalized", "normalised score (0 random, 100 expert)", "{:.1f}")
#: Columns added when a row is of a moving twin.
MOVING_COLUMNS = (
    ("wall_collisions", "wall collisions/ep", "{:.2f}"),
    ("mover_collisions", "mover collisions/ep", "{:.2f}"),
    ("mover_hits", "mover hits/ep", "{:.2f}"),
)


def markdown_table(rows: Sequence[dict[str, Any]]) -> str:
    """Rows ``{"case": ..., **Metrics.to_dict()}`` as a Markdown table (with the normalised score after SPL, and the
    mover columns, when a row has them)."""
    columns = COLUMNS + (MOVING_COLUMNS if any(row.get("mover_hits") is not None for row in rows) else ())
    if any("normalized" in row for row in rows):
        at = [c[0] for c in columns].index("spl") + 1
        columns = (*columns[:at], NORMALIZED_COLUMN, *columns[at:])
    head = ["case"] + [c[1] for c in columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [str(row["case"])]
        for key, _, fmt in columns:
            v = row.get(key)
            cells.append("-" if v is None else fmt.format(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_results(
    rows: list[dict[str, Any]], out: Path, config: dict[str, Any], name: str = "results", missing: Sequence[str] = ()
) -> str:
    """``<name>.json`` (rows + config), ``<name>.md`` and ``config.json`` in ``out``; returns the Markdown table.
    ``missing``: twins asked for but not built, named under the table (and in the JSON) so a table without them
    never reads as complete."""
    out.mkdir(parents=True, exist_ok=True)
    record = {"config": config, "results": rows, **({"not_evaluated": list(missing)} if missing else {})}
    write_atomic(out / f"{name}.json", json.dumps(record, indent=2) + "\n")
    md = markdown_table(rows)
    if missing:
        md += (
            "\nNot evaluated (not built here): "
            + ", ".join(missing)
            + "; `make dataset SCENE=<scene> VARIANT=<variant>`.\n"
        )
    write_atomic(out / f"{name}.md", md)
    write_atomic(out / "config.json", json.dumps(config, indent=2) + "\n")
    return md


def cross_matrix(
    policies: dict[str, Policy],
    datasets: dict[str, Dataset],
    *,
    pairs: int = 500,
    seed: int = 2024,
    max_steps: int | None = None,
) -> dict[str, Any]:
    """Evaluate every policy on every dataset (e.g. train on quadrant Qi, evaluate on Qj).

    Returns ``{"rows": [train names], "cols": [dataset names], "success": [[...]], "spl": [[...]]}``.
    """
    rows, cols = list(policies), list(datasets)
    succ = np.zeros((len(rows), len(cols)))
    spl_m = np.zeros_like(succ)
    for i, r in enumerate(rows):
        for j, c in enumerate(cols):
            m, _ = evaluate(policies[r], datasets[c], pairs=pairs, seed=seed, max_steps=max_steps, latency=False)
            succ[i, j], spl_m[i, j] = m.success_rate, m.spl
    return {"rows": rows, "cols": cols, "success": succ.tolist(), "spl": spl_m.tolist()}
