"""One navigation table: every twin x {the default agent, SB3 DQN, the classical planner} x measurement noise.

For each scene and seed, train each ``--presets`` agent (default: ``DEFAULT_PRESET``) on the blueprint for ``--steps``
(default 0: each preset's own budget, the default's growing with the twin's free cells), and Stable-Baselines3's DQN
with its defaults on our gymnasium env (seed 0, capped at
``--sb3-seconds`` of wall time: what a user would otherwise run); then evaluate them and the fingerprint +
breadth-first planner on 500 seeded pairs of the blueprint and the dynamic twin (where the scene has one) under
every ``--noise`` level, and, where ``<scene>-txpose`` was built (``python -m dtradar_data build --scene <scene>
--tx-pose-error 0.5 5``), on the twin whose transmitter is 0.5 m and 5 degrees off (row ``tx pose``): success, SPL,
collisions, decision p50 / p99 and training time. Trainings run first, ``--jobs`` at a time, each single-threaded;
a run whose ``model.pt`` exists under ``--runs`` with the same settings is reused. The evaluations run after them,
single-threaded. Writes ``results/<name>.{json,md,png}`` (mean ± spread over seeds).

    python bench/bench_nav.py --scenes cubicle meeting dallas-q1 dallas-q2 dallas-q3 dallas-q4 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch

from dtradar_data.core.errors import DatasetNotFoundError, UnknownNameError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.checkpoints import save_checkpoint
from dtradar_rl.agents.planner import planner_for_scene
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, PAPER_BUDGET, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.plots import _save, plt

GOALS = {"blueprint": (0.99, 0.95), "dynamic": (0.95, None)}  # success, SPL (issue: cities at the indoor standard)
SB3 = "SB3 DQN"
POSE = "tx pose"  # the noise column of the rows on the <scene>-txpose twins
POSE_SUFFIX = "-txpose"


def trained(scene: str, seed: int, preset: str, steps: int, runs: str, threads: int) -> tuple[str, float | None]:
    """``model.pt`` of ``preset`` on ``scene``'s blueprint (trained, or reused when its ``train.json`` matches)."""
    out = Path(runs) / preset / scene / f"s{seed}"
    ckpt, summary = out / "model.pt", out / "train.json"
    if ckpt.is_file() and summary.is_file():
        saved = json.loads(summary.read_text())
        if saved.get("preset") == preset and saved.get("steps") == steps:
            return str(ckpt), saved.get("train_s")
    torch.set_num_threads(threads)
    cfg = config_for(
        preset,
        scene=scene,
        seed=seed,
        **({"total_env_steps": steps} if steps else {}),  # 0: the preset's own budget
        out=str(out),
        verbose=False,
        threads=threads,
        checkpoint_every=0,
        save_replay=False,
    )
    result = train(cfg)
    write_atomic(summary, json.dumps({"preset": preset, "steps": steps, "train_s": result.wall_s}) + "\n")
    return str(result.checkpoint), result.wall_s


def sb3_trained(scene: str, seed: int, steps: int, seconds: float, runs: str) -> tuple[str, float | None]:
    """Stable-Baselines3 DQN (its defaults; our ``tuned`` preset's observations, reward, network and gamma) on
    ``scene``'s blueprint for ``steps`` or ``seconds``, whichever ends first, saved as one of our checkpoints so it
    is evaluated (and timed) exactly like ours."""
    from bench_rl import sb3_dqn  # the same SB3 set-up as make bench-rl (bench/ is on the path of these scripts)
    from stable_baselines3.common.callbacks import BaseCallback

    out = Path(runs) / "sb3" / scene / f"s{seed}"
    ckpt, summary = out / "model.pt", out / "train.json"
    if ckpt.is_file() and summary.is_file():
        saved = json.loads(summary.read_text())
        if saved.get("steps") == steps and saved.get("seconds") == seconds:
            return str(ckpt), saved.get("train_s")
    torch.set_num_threads(1)
    ds = load_dataset(f"{scene}/blueprint")
    cfg = config_for("tuned", scene=scene, seed=seed, total_env_steps=steps)
    norm = Normalizer.fit(ds)
    env = DtradarNavEnv(ds, obs=cfg.obs, reward=cfg.reward, normalizer=norm)

    class Cap(BaseCallback):
        def __init__(self):
            super().__init__()
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < seconds

    model = sb3_dqn(env, cfg, seed)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, callback=Cap())
    wall = time.perf_counter() - t0
    from dtradar_rl.agents.policy import QNetwork

    q = QNetwork(env.observation_space.shape[0], tuple(cfg.hidden))
    # SB3's q_net.q_net is the same [Linear, ReLU] x n -> Linear stack as ours
    q.net.load_state_dict({k.removeprefix("q_net."): v for k, v in model.q_net.q_net.state_dict().items()})
    stats = {"trainer": "stable-baselines3 DQN (defaults)", "env_steps": int(model.num_timesteps), "wall_s": wall}
    save_checkpoint(ckpt, q, cfg, norm, env.table.names, ds, stats=stats)
    write_atomic(
        summary,
        json.dumps({"steps": steps, "seconds": seconds, "train_s": wall, "env_steps": int(model.num_timesteps)}) + "\n",
    )
    return str(ckpt), wall


def _twins(scene: str) -> dict[str, object]:
    twins = {}
    for key, name in (
        ("blueprint", f"{scene}/blueprint"),
        ("dynamic", f"{scene}/dynamic"),
        ("blueprint" + POSE_SUFFIX, f"{scene}{POSE_SUFFIX}/blueprint"),
        ("dynamic" + POSE_SUFFIX, f"{scene}{POSE_SUFFIX}/dynamic"),
    ):
        try:
            twins[key] = load_dataset(name)
        except (DatasetNotFoundError, UnknownNameError):  # not built (a pose twin is unknown until it is)
            pass
    return twins


def main() -> None:
    args = _parser().parse_args()
    _check_before_training(args)
    m_start = machine()
    runs = _train_all(args)
    if args.train_only:
        return
    torch.set_num_threads(1)  # the evaluations: 500 robots at once gain nothing from a second thread on 2 cores
    rows = []
    for scene in args.scenes:
        twins = _twins(scene)
        planner = None if args.no_planner else planner_for_scene(scene)
        for seed in args.seeds:
            for agent, (policy, train_s) in _agents(scene, seed, runs, planner, args).items():
                rows += _evaluated(scene, seed, agent, policy, train_s, twins, args)
    result = {
        "args": vars(args),
        "rows": rows,
        "machine": {"start": m_start, "end": machine()},
        "goals": GOALS,
        "command": "python bench/bench_nav.py " + " ".join(sys.argv[1:]),
        "load_before": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }
    _write(result, Path(args.out), args.name)


def _parser() -> argparse.ArgumentParser:
    """The options; the module's docstring is the ``--help`` text (``--preset`` is the old spelling, kept hidden)."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--scenes", nargs="+", default=["cubicle", "meeting", "dallas-q1", "dallas-q2", "dallas-q3", "dallas-q4"]
    )
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--presets", nargs="+", default=[DEFAULT_PRESET], help="our agents, side by side")
    ap.add_argument("--preset", dest="presets", action="store", type=lambda p: [p], help=argparse.SUPPRESS)
    ap.add_argument(
        "--steps", type=int, default=0, help="budget of our agents (0: each preset's own; SB3's: the paper's 600K)"
    )
    ap.add_argument("--noise", nargs="+", default=["none", "realistic"])
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--sb3-seconds", type=float, default=300.0, help="wall-time cap of each SB3 run (0 = no SB3)")
    ap.add_argument("--no-planner", action="store_true")
    ap.add_argument("--train-only", action="store_true", help="train (or find) every run, evaluate nothing")
    ap.add_argument("--jobs", type=int, default=1, help="trainings at once (each single-threaded)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads of each training")
    ap.add_argument("--runs", default=str(run_dir("bench_nav")))
    ap.add_argument("--out", default="results")
    ap.add_argument("--name", default="bench_nav", help="stem of the result files")
    return ap


def _check_before_training(args) -> None:
    """Fail before hours of training, not after: a repeated seed, or a scene whose blueprint is not built."""
    if len(set(args.seeds)) != len(args.seeds):
        sys.exit(f"--seeds repeats a seed ({args.seeds}): one run would be counted twice")
    for scene in args.scenes:
        load_dataset(f"{scene}/blueprint")


def _train_all(args) -> dict[tuple, tuple[str, float | None]]:
    """Every (scene, seed, agent)'s checkpoint and training seconds. Trainings first (the long part), ``--jobs`` at
    a time, in fresh processes so their threads are their own; SB3 on the first seed only."""
    jobs = [(scene, seed, p) for scene in args.scenes for seed in args.seeds for p in args.presets]
    if args.sb3_seconds > 0:
        jobs += [(scene, args.seeds[0], SB3) for scene in args.scenes]
    runs: dict[tuple, tuple[str, float | None]] = {}
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {
            job: (
                pool.submit(sb3_trained, job[0], job[1], args.steps or PAPER_BUDGET, args.sb3_seconds, args.runs)
                if job[2] == SB3
                else pool.submit(trained, *job, args.steps, args.runs, args.threads)
            )
            for job in jobs
        }
        for job, fut in futures.items():
            runs[job] = fut.result()
            print(f"trained {job[0]} s{job[1]} {job[2]}: {runs[job][1]:.0f} s", flush=True)
    print(f"trainings: {time.perf_counter() - t0:.0f} s wall, {args.jobs} at a time", flush=True)
    return runs


def _agents(scene: str, seed: int, runs: dict, planner, args) -> dict[str, tuple[object, float | None]]:
    """The policies evaluated for one scene and seed, with their training seconds: our presets, and on the first
    seed SB3 and the planner (they have no seed of their own)."""
    agents = {p: (load_policy(runs[(scene, seed, p)][0]), runs[(scene, seed, p)][1]) for p in args.presets}
    if seed == args.seeds[0]:  # no seed of their own
        if (scene, seed, SB3) in runs:
            agents[SB3] = (load_policy(runs[(scene, seed, SB3)][0]), runs[(scene, seed, SB3)][1])
        if planner is not None:
            agents["planner"] = (planner, None)
    return agents


def _evaluated(scene: str, seed: int, agent: str, policy, train_s, twins: dict, args) -> list[dict]:
    """One agent on every built twin under every ``--noise`` level, then on the pose twins without noise (their
    error is the pose, not the measurements); a row each, printed as it comes."""
    rows = []
    cases = [(n, v) for n in args.noise for v in ("blueprint", "dynamic") if v in twins]
    cases += [(POSE, v) for v in ("blueprint", "dynamic") if v + POSE_SUFFIX in twins]
    for noise, variant in cases:
        ds = twins[variant + POSE_SUFFIX] if noise == POSE else twins[variant]
        m, _ = evaluate(policy, ds, pairs=args.pairs, noise="none" if noise == POSE else noise)
        rows.append(
            {
                "scene": scene,
                "seed": seed,
                "agent": agent,
                "noise": noise,
                "twin": variant,
                "dataset": f"{ds.name}@{(ds.version or '-')[:12]}",
                "success": m.success_rate,
                "spl": m.spl,
                "collisions": m.collisions,
                "p50_ms": m.latency_ms,
                "p99_ms": m.latency_p99_ms,
                "train_s": train_s,
            }
        )
        print(
            f"{scene:14s} s{seed} {agent:20s} {noise:9s} {variant:9s} success {m.success_rate:.3f}"
            f" SPL {m.spl:.3f} collisions {m.collisions:.2f} p50 {m.latency_ms:.3f} ms",
            flush=True,
        )
    return rows


def _write(result: dict, out: Path, name: str) -> None:
    """``<name>.json``, ``.md`` and ``.png`` under ``out``, then the table printed."""
    out.mkdir(parents=True, exist_ok=True)
    stem = out / name
    write_atomic(stem.with_suffix(".json"), json.dumps(result, indent=2) + "\n")
    md = markdown(result)
    write_atomic(stem.with_suffix(".md"), md)
    plot(result, stem.with_suffix(".png"))
    print(md, end="")
    print(f"results: {stem}.json, .md, .png")


def _groups(rows):
    keys = list(dict.fromkeys((r["scene"], r["agent"], r["noise"]) for r in rows))
    for k in keys:
        yield k, [r for r in rows if (r["scene"], r["agent"], r["noise"]) == k]


def _pm(values, fmt="{:.3f}"):
    v = np.asarray([x for x in values if x is not None], float)
    if v.size == 0:
        return "-"
    return fmt.format(v.mean()) + (f" ± {fmt.format(v.std())}" if v.size > 1 else "")


def _budget(steps: int) -> str:
    return f"{steps:,} training steps" if steps else "each preset's own training budget"


def markdown(result) -> str:
    a = result["args"]
    lines = [
        f"## Navigation on every twin ({a['pairs']} seeded pairs per twin, seeds {' '.join(map(str, a['seeds']))}, "
        f"{_budget(a['steps'])}; {describe(result['machine']['start'])})",
        "",
        f"`{result.get('command', 'python bench/bench_nav.py')}`."
        + (
            f" `{POSE}`: the twin re-traced with its transmitter 0.5 m and 5° off (no noise)."
            if any(r["noise"] == POSE for r in result["rows"])
            else ""
        )
        + (
            f" {SB3}: seed 0, Stable-Baselines3 defaults, its training capped at {a['sb3_seconds']:.0f} s of wall time."
            if any(r["agent"] == SB3 for r in result["rows"])
            else ""
        ),
        "",
        "| twin | agent | noise | blueprint: success / SPL | dynamic: success / SPL / collisions | decision p50 / p99 "
        "(ms) | training (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for (scene, agent, noise), rs in _groups(result["rows"]):
        bp = [r for r in rs if r["twin"] == "blueprint"]
        dy = [r for r in rs if r["twin"] == "dynamic"]
        bp_cell, dy_cell = _twin_cells(rs)
        lat = f"{_pm(r['p50_ms'] for r in rs)} / {_pm(r['p99_ms'] for r in rs)}"
        train_rows = bp or dy
        lines.append(
            f"| {scene} | {agent} | {noise} | {bp_cell} | {dy_cell} | {lat} | "
            f"{_pm((r['train_s'] for r in train_rows), '{:.0f}')} |"
        )
    lines += ["", "Goals: blueprint success ≥ 0.99 and SPL ≥ 0.95 on every twin, dynamic success ≥ 0.95 (Dallas Q3)."]
    return "\n".join(lines) + "\n"


def _twin_cells(rs: list[dict]) -> tuple[str, str]:
    """One group's blueprint "success / SPL" and dynamic "success / SPL / collisions" cells (mean ± spread over
    seeds; "-" where the group has no row of that twin)."""
    bp = [r for r in rs if r["twin"] == "blueprint"]
    dy = [r for r in rs if r["twin"] == "dynamic"]
    bp_cell = f"{_pm(r['success'] for r in bp)} / {_pm(r['spl'] for r in bp)}" if bp else "-"
    dy_cell = (
        f"{_pm(r['success'] for r in dy)} / {_pm(r['spl'] for r in dy)} / "
        f"{_pm((r['collisions'] for r in dy), '{:.2f}')}"
        if dy
        else "-"
    )
    return bp_cell, dy_cell


def agent_table(result, agent: str = SB3, noise: str = "none") -> str:
    """One agent's rows under one noise level: a row per twin, its blueprint success / SPL and dynamic success / SPL
    / collisions (mean ± spread over seeds)."""
    lines = ["| twin | blueprint: success / SPL | dynamic: success / SPL / collisions |", "|---|---|---|"]
    for (scene, name, level), rs in _groups(result["rows"]):
        if (name, level) != (agent, noise):
            continue
        bp_cell, dy_cell = _twin_cells(rs)
        lines.append(f"| {scene} | {bp_cell} | {dy_cell} |")
    return "\n".join(lines) + "\n"


def plot(result, path: Path) -> Path:
    rows = result["rows"]
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    agents = list(dict.fromkeys(r["agent"] for r in rows))
    noises = list(dict.fromkeys(r["noise"] for r in rows))
    fig, axes = plt.subplots(2, len(noises), figsize=(4.5 * len(noises), 6.5), sharey=True, squeeze=False)
    width = 0.8 / max(1, len(agents))
    for col, noise in enumerate(noises):
        for row, twin in enumerate(("blueprint", "dynamic")):
            ax = axes[row, col]
            for j, agent in enumerate(agents):
                xs, ys, es = [], [], []
                for i, scene in enumerate(scenes):
                    v = [
                        r["success"]
                        for r in rows
                        if (r["scene"], r["agent"], r["noise"], r["twin"]) == (scene, agent, noise, twin)
                    ]
                    if v:
                        xs.append(i + (j - (len(agents) - 1) / 2) * width)
                        ys.append(np.mean(v))
                        es.append(np.std(v) if len(v) > 1 else 0.0)
                if xs:
                    ax.bar(xs, ys, width, yerr=es, color=f"C{j}", label=agent if (row, col) == (0, 0) else None)
            ax.axhline(GOALS[twin][0], color="k", ls=":", lw=1)
            ax.set_xticks(range(len(scenes)), scenes, fontsize=7, rotation=30)
            ax.set_ylim(0.0, 1.02)
            ax.set_title(f"{twin}, noise: {noise}", fontsize=9)
            if col == 0:
                ax.set_ylabel("success")
    fig.legend(loc="upper center", ncol=len(agents), fontsize=8)
    fig.suptitle("success on every twin (dotted: goals)", y=0.005, va="bottom", fontsize=9)
    fig.tight_layout(rect=(0, 0.03, 1, 0.95))
    return _save(fig, path)


if __name__ == "__main__":
    main()
