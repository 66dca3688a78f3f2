"""``make solve SCENE=<scene>``: the exact solution of a twin's MDP, and what its greedy policy reaches.

    python -m dtradar_rl solve --scene cubicle                      # V*/Q* for every target, both rewards
    python -m dtradar_rl solve --scene dallas-q3 --rewards geodesic --gamma 0.99

For every twin in ``--variants`` and every reward in ``--rewards``: V* and Q* for every (cell, target) at discount
``--gamma`` (:mod:`dtradar_rl.tabular.solver`; cached in ``<data root>/tabular/`` by :mod:`dtradar_rl.tabular.cache`,
reused when the twin's content version, reward and discount are the same and every file matches its recorded hash,
else solved again and rewritten, saying so on stderr), then the greedy Q* policy followed from the 500 seeded
evaluation pairs of ``make eval`` with the true cell: its success rate and SPL, and the fraction of connected pairs it
reaches.
Writes ``solve.json``, ``solve.md`` and, per twin and reward, ``value_<variant>_<reward>.png`` (V* of one target as a
heat map, the greedy policy as arrows) to ``--out``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core.errors import DatasetNotFoundError
from dtradar_data.core.files import write_atomic
from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.evaluation.normalized import DEFAULT_PAIRS, DEFAULT_SEED
from dtradar_rl.tabular.cache import solve_twin
from dtradar_rl.tabular.evaluation import follow, path_metrics
from dtradar_rl.tabular.memory import check_memory, solve_parts
from dtradar_rl.tabular.solver import GAMMA, Solution, TabularMDP, check_gamma, check_size
from dtradar_rl.task.config import Config, ConfigError, check_unique
from dtradar_rl.task.rewards import check_reward
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.viz.value_map import plot_value_grid


@dataclass(frozen=True)
class SolveConfig(Config):
    """Solve a twin's navigation MDP exactly: V*/Q* for every (cell, target), the greedy policy's success and SPL."""

    scene: str = "cubicle"
    """scene whose twins are solved (synthetic-<nx>x<ny> for a stand-in without a ray tracer)"""
    variants: tuple[str, ...] = ()
    """static twins to solve (default: the blueprint and, where it is built, the dynamic twin; a moving twin is
    refused: its MDP is in space-time)"""
    rewards: tuple[str, ...] = ("geodesic", "paper")
    """rewards to solve under (paper, scaled, euclidean, geodesic)"""
    gamma: float = GAMMA
    """discount (the paper's 0.9; the return-based normalised score uses it too)"""
    pairs: int = DEFAULT_PAIRS
    """seeded evaluation pairs the greedy policy is followed from (500 = those of make eval)"""
    cache: bool = True
    """reuse a stored solution of the same twin version, reward and discount (--no-cache: solve again)"""
    out: str = ""
    """output folder (default results/solve/<scene>)"""
    verbose: bool = True
    """print progress"""

    @property
    def out_dir(self) -> Path:
        return Path(self.out or f"results/solve/{self.scene}")

    def check_ranges(self) -> None:
        super().check_ranges()
        # each value is one row of the table (one solve): a repeated one was solved and printed twice
        for name in ("rewards", "variants"):
            check_unique(getattr(self, name), name)

    def validate(self) -> SolveConfig:
        for r in self.rewards:
            check_reward(r)
        check_gamma(self.gamma)
        if not self.rewards:
            raise ConfigError("--rewards must list at least one value")
        if self.pairs < 1:
            raise ConfigError("--pairs must be >= 1")
        return self


def greedy_metrics(sol: Solution, tab: TabularMDP, pairs: np.ndarray) -> dict[str, float]:
    """The greedy Q* policy followed from ``pairs`` with the true cell, capped at the twin's step limit."""
    rows = np.searchsorted(sol.targets, pairs[:, 1])
    greedy = sol.greedy()
    m = path_metrics(follow(tab, greedy, rows, pairs[:, 0], pairs[:, 1], tab.mdp.max_steps))
    return {**m, "connected_reached": m["success_rate"]}  # every evaluation pair is connected by construction


def value_picture(sol: Solution, tab: TabularMDP, pair: np.ndarray, path: Path) -> Path:
    """V* of the pair's target over the grid, the greedy moves as arrows and the greedy path from its start."""
    start, target = (int(c) for c in pair)
    row = sol.row(target)
    h, w = tab.mdp.blocked.shape
    values = np.full(h * w, np.nan)
    values[tab.cells] = sol.values[row]
    values[target] = np.nan if tab.mdp.blocked.ravel()[target] else values[target]
    greedy = sol.q(np.array([row]))[0].argmax(-1)
    actions = np.full(h * w, -1, np.int64)
    actions[tab.cells] = greedy
    actions[target] = -1
    route, s = [start], tab.state_of[start]
    for _ in range(tab.mdp.max_steps):
        if tab.cells[s] == target:
            break
        s = tab.next[s, greedy[s]]
        route.append(int(tab.cells[s]))
    xy = np.stack(tab.mdp.xy(np.array(route)), 1)
    return plot_value_grid(
        values.reshape(h, w),
        actions.reshape(h, w),
        tab.mdp.xy(target),
        path,
        start=tab.mdp.xy(start),
        route=xy,
        title=f"{sol.name}: V* of target {tuple(int(v) for v in tab.mdp.xy(target))} ({sol.reward}, γ {sol.gamma})",
    )


def twins(cfg: SolveConfig, say) -> dict[str, Any]:
    """The twins to solve, all loaded before any work: ``--variants``, or the blueprint and the dynamic twin where it
    is built (a city quadrant without vehicles has none)."""
    if cfg.variants:
        return {v: load_dataset(f"{cfg.scene}/{v}") for v in cfg.variants}
    out = {"blueprint": load_dataset(f"{cfg.scene}/blueprint")}
    try:
        out["dynamic"] = load_dataset(f"{cfg.scene}/dynamic")
    except DatasetNotFoundError as e:
        say(f"{cfg.scene}/dynamic is not solved: {e.message}")
    return out


def check_solve_memory(cfg: SolveConfig, loaded: dict[str, Any], tabs: dict[str, TabularMDP]) -> None:
    """:class:`~dtradar_rl.tabular.memory.TooLargeError` before the first twin is solved when the largest one's V*
    for every target, its greedy table and a chunk's working arrays (solved one twin and reward at a time) would
    not fit this machine's available memory."""
    variant = max(tabs, key=lambda v: tabs[v].n)
    n = tabs[variant].n
    check_size(n, n)
    check_memory(
        f"solving {loaded[variant].name} exactly ({n:,} cells, each a target)",
        solve_parts(n, n, greedy=True),
        hint=f"solve a twin of coarser cells (build {cfg.scene} again with a larger --cell-m) or another scene",
    )


def solve_scene(cfg: SolveConfig) -> dict[str, Any]:
    """Run ``cfg``; returns (and writes) the result."""
    cfg = cfg.validate()
    say = print if cfg.verbose else (lambda *a, **k: None)
    out = cfg.out_dir
    t_start = time.perf_counter()
    rows: list[dict[str, Any]] = []
    loaded = twins(cfg, say)
    tabs = {variant: TabularMDP.from_dataset(ds) for variant, ds in loaded.items()}
    check_solve_memory(cfg, loaded, tabs)
    for variant, ds in loaded.items():
        tab = tabs[variant]
        pairs = sample_eval_pairs(ds, cfg.pairs, DEFAULT_SEED)
        for reward in cfg.rewards:
            t0 = time.perf_counter()
            sol, folder, cached = solve_twin(ds, reward, cfg.gamma, cache=cfg.cache)
            solve_s = time.perf_counter() - t0
            m = greedy_metrics(sol, tab, pairs)
            picture = value_picture(sol, tab, pairs[0], out / f"value_{variant}_{reward}.png")
            row = {
                "dataset": ds.name,
                "version": ds.version,
                "reward": reward,
                "gamma": cfg.gamma,
                "cells": tab.n,
                "targets": int(sol.targets.size),
                "sweeps": sol.sweeps,
                "residual": sol.residual,
                "solve_s": sol.seconds,
                "wall_s": solve_s,
                "cached": cached,
                "solution": str(folder),
                "picture": str(picture),
                **m,
            }
            rows.append(row)
            say(
                f"{ds.name} ({reward}, γ {cfg.gamma}): V*/Q* for {tab.n} cells x {sol.targets.size} targets "
                + ("from the cache" if cached else f"in {sol.seconds:.2f} s ({sol.sweeps} sweeps)")
                + (f" -> {folder}" if (folder / "solution.json").is_file() else " (not stored)")
                + f"; greedy on {len(pairs)} pairs: success {m['success_rate']:.3f}, SPL {m['spl']:.3f}"
            )
            sol = None  # freed before the next solve: check_solve_memory counts one solution at a time
    result = {
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.__dict__.items()},
        "rows": rows,
        "machine": machine(),
        "wall_s": time.perf_counter() - t_start,
    }
    write_atomic(out / "solve.json", json.dumps(result, indent=2) + "\n")
    write_atomic(out / "solve.md", markdown(result))
    say(markdown(result), end="")
    return result


def markdown(result: dict[str, Any]) -> str:
    cfg = result["config"]
    lines = [
        f"Exact solution of `{cfg['scene']}` (γ = {cfg['gamma']}); the greedy Q* policy followed from "
        f"{cfg['pairs']} seeded evaluation pairs (seed {DEFAULT_SEED}) with the true cell.",
        "",
        "| twin | reward | cells × targets | solve (s) | sweeps | success | SPL |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for r in result["rows"]:
        when = "cached" if r["cached"] else f"{r['solve_s']:.2f}"
        lines.append(
            f"| {r['dataset']} | {r['reward']} | {r['cells']} × {r['targets']} | {when} | {r['sweeps']} | "
            f"{r['success_rate']:.3f} | {r['spl']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def _seconds(x: float) -> str:
    """Two decimals under 10 s (trailing zeros dropped, one kept), one under 100 s, none above: ``0.42``, ``1.0``,
    ``8.3``, ``20.2``, ``137``."""
    if x >= 10:
        return f"{x:.1f}" if x < 100 else f"{x:.0f}"
    said = f"{x:.2f}".rstrip("0")
    return said + "0" if said.endswith(".") else said


def twins_table(results: list[dict[str, Any]]) -> str:
    """Several scenes' ``solve.json`` in one table (docs/results/tabular.md), a row per twin in their order: its size,
    the solve time under each reward and the greedy policy's success / SPL under each (the discount named for every
    reward but ``geodesic``, whose greedy policy is the shortest path at any)."""
    rewards = list(results[0]["config"]["rewards"])
    gamma = results[0]["config"]["gamma"]
    twins: dict[str, dict[str, dict[str, Any]]] = {}
    for result in results:
        for r in result["rows"]:
            twins.setdefault(r["dataset"], {})[r["reward"]] = r

    def k(n: int) -> str:
        return f"{n:,}".replace(",", " ")

    head = ["twin", "cells × targets", *(f"solve, {w}" for w in rewards)] + [
        f"greedy under `{w}`" + ("" if w == "geodesic" else f" (γ {gamma:g})") + ": success / SPL" for w in rewards
    ]
    lines = ["| " + " | ".join(head) + " |", "|---|---|" + "---:|" * len(rewards) + "---|" * len(rewards)]
    for name, by in twins.items():
        r0 = next(iter(by.values()))
        cells = [name, f"{k(r0['cells'])} × {k(r0['targets'])}"]
        cells += [f"{_seconds(by[w]['solve_s'])} s" if w in by else "-" for w in rewards]
        cells += [f"{by[w]['success_rate']:.3f} / {by[w]['spl']:.3f}" if w in by else "-" for w in rewards]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


__all__ = ["SolveConfig", "check_solve_memory", "greedy_metrics", "solve_scene", "twins_table"]
