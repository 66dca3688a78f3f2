"""RL benchmark, side by side in one run: batched env throughput, decision latency, and the paper's training budget.

    python bench/bench_rl.py                 # `make bench-rl`; writes results/bench_rl.json and results/bench_rl.md
    python bench/bench_rl.py --scene meeting # -> results/bench_rl_meeting.{json,md}
    python bench/bench_rl.py --env-only      # env throughput only -> results/bench_rl_env.{json,md}
    python bench/bench_rl.py --no-robust --name bench_rl_memory  # -> results/bench_rl_memory.{json,md}
    python bench/bench_rl.py --help

Measures (paper figures in brackets): env steps/s of the batched torch env (its fast path and, side by side, its
general path: ``fast_path=False``; optionally at other torch thread counts) vs the gymnasium env; one greedy
decision (vs the paper's 17 ms); wall time of the paper's budget of 600K env steps with the tuned DQN (vs the paper's
46 min) and the success rate / SPL it reaches on blueprint -> blueprint and blueprint -> dynamic; the same for the
``robust`` preset (random extra obstacles while training; ``--no-robust`` skips it); and the same budget
with Stable-Baselines3 DQN on our gymnasium env (what a user would otherwise run), capped in wall time and
extrapolated when the cap is hit. Uses the real ``<scene>/blueprint`` twin when it is built, otherwise the synthetic
42x18 cubicle-sized stand-in, and says which.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import torch
import tyro
from bench_rl_report import _header, _throughput_rows, render_markdown  # beside this script in bench/ (on its path)

from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import write_atomic
from dtradar_rl.agents.policy import Policy
from dtradar_rl.envs.batched import BatchedNavEnv
from dtradar_rl.envs.nav_env import DtradarNavEnv
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.observations import Normalizer
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import auto_threads, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.train.saved_runs import load_policy

PAPER_TRAIN_S = 46 * 60.0
#: Steps of random actions drawn before a batched throughput measurement (more than an episode's 240-step cap on the
#: cubicle, so no robot replays its own moves within an episode): drawing 4 096 actions with torch's CPU generator
#: costs ~15-30 us a step (measured, 1 thread), a tenth of the env's step; that is the agent's cost, not the env's.
ACTION_BANK = 256
PAPER_DECISION_MS = 17.0


@dataclass(frozen=True)
class BenchConfig:
    """Benchmark of dtradar_rl (see the module docstring)."""

    scene: str = "cubicle"
    """scene to benchmark on; falls back to the synthetic 42x18 stand-in when <scene>/blueprint is not built"""
    budget: int = 600_000
    """training budget in environment steps (the paper's: 600K)"""
    env_counts: tuple[int, ...] = (1, 256, 4096)
    """batched env sizes whose throughput is measured"""
    env_seconds: float = 2.0
    """seconds per throughput measurement (split into env_rounds interleaved rounds; the median round is reported)"""
    env_rounds: int = 5
    """interleaved rounds of the throughput measurements (every variant once per round, so load hits all alike)"""
    env_general: bool = True
    """also measure the batched env's general path (fast_path=False), side by side with the fast path"""
    env_threads: tuple[int, ...] = (1, 2)
    """also measure the batched env (fast path) at these torch thread counts (other than --threads), interleaved
    with the rest: on 2 shared cores 2 threads collapse at 4 096 robots when another process holds a core"""
    env_only: bool = False
    """only measure the env throughput (no training); writes <stem>_env.{json,md}"""
    pairs: int = 500
    """seeded (start, target) evaluation pairs per twin"""
    robust: bool = True
    """also train the robust preset (tuned + random extra obstacles while training) with the same budget, and
    report it side by side with the tuned agent"""
    default: bool = True
    """also train the default preset (what `make train` runs: the memory agent with noise) with the same budget, and
    report its wall time beside SB3's (the run a user gets, so the ratio a user sees)"""
    sb3: bool = True
    """also train Stable-Baselines3 DQN with the same budget on the gymnasium env"""
    sb3_max_seconds: float = 300.0
    """wall-time cap of the SB3 run (its time for the full budget is extrapolated when hit)"""
    sb3_threads: tuple[int, ...] = ()
    """torch threads of the SB3 runs, one run each (empty: ours' threads); the ratios are taken against the fastest,
    so SB3 is compared at the thread count that suits it best (its batches of 32 may prefer one thread)"""
    threads: int = 0
    """torch threads (0 = auto)"""
    out: str = "results"
    """where bench_rl.{json,md} go (bench_rl_<scene>.{json,md} for a scene other than the cubicle)"""
    name: str = ""
    """stem of the result files instead (a run of other options beside the default run: its own JSON)"""
    runs: str = str(run_dir("bench_rl"))
    """where the benchmark's checkpoints go"""


def _datasets(scene: str):
    try:
        bp = load_dataset(f"{scene}/blueprint")
        try:
            dyn = load_dataset(f"{scene}/dynamic")
        except DtradarError:
            dyn = None
        return bp, dyn, False
    except DtradarError as e:  # not built here: synthetic stand-in
        print(f"{scene}/blueprint not available ({type(e).__name__}); using the synthetic 42x18 stand-in")
        return load_dataset("synthetic/blueprint"), load_dataset("synthetic/dynamic"), True


def env_throughput(
    ds,
    counts,
    seconds,
    obs="neighbors",
    reward="geodesic",
    *,
    rounds: int = 1,
    general: bool = False,
    threads: tuple[int, ...] = (),
) -> dict:
    """Env steps/s with random actions: the gymnasium env (``gymnasium``) and the batched env at each size in
    ``counts`` (``batched_<k>``: step, ``reset_where(te | tr)``, ``observe()``, as a training loop does; the actions
    come from a bank of :data:`ACTION_BANK` random steps drawn beforehand); with
    ``general`` also its general path (``batched_general_<k>``), and its fast path at each torch thread count in
    ``threads`` (``batched_<k>_t<n>``). Every variant runs ``seconds / rounds`` once per round, interleaved; the
    median round is reported."""

    def gym_round(env, seconds):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            for _ in range(500):
                _, _, te, tr, _ = env.step(int(env.action_space.sample()))
                if te or tr:
                    env.reset()
            n += 500
        return n / (time.perf_counter() - t0)

    def batched_round(benv, bank, at, seconds):
        k, steps, t0 = benv.num_envs, 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            _, _, te, tr, _ = benv.step(bank[at[0] % ACTION_BANK])
            benv.reset_where(te | tr)
            benv.observe()
            at[0] += 1
            steps += k
        return steps / (time.perf_counter() - t0)

    env = DtradarNavEnv(ds, obs=obs, reward=reward)
    env.reset(seed=0)
    variants = {"gymnasium": (lambda s, env=env: gym_round(env, s), None)}
    base = torch.get_num_threads()
    for k in counts:
        for key, fast, nthreads in (
            [(f"batched_{k}", True, base)]
            + ([(f"batched_general_{k}", False, base)] if general else [])
            + [(f"batched_{k}_t{t}", True, t) for t in threads if t != base]
        ):
            benv = BatchedNavEnv.from_dataset(ds, k, obs=obs, reward=reward, seed=0, fast_path=fast)
            benv.reset()
            bank = torch.randint(4, (ACTION_BANK, k), generator=torch.Generator().manual_seed(0))
            variants[key] = (lambda s, benv=benv, bank=bank, at=[0]: batched_round(benv, bank, at, s), nthreads)
    rates: dict[str, list[float]] = {key: [] for key in variants}
    for _ in range(max(1, rounds)):
        for key, (run, nthreads) in variants.items():
            torch.set_num_threads(nthreads or base)
            rates[key].append(run(seconds / max(1, rounds)))
    torch.set_num_threads(base)
    return {key: sorted(r)[len(r) // 2] for key, r in rates.items()}


def sb3_dqn(env, ours_cfg, seed: int = 0):
    """Stable-Baselines3's DQN with its defaults on ``env``, given our config's network, gamma and warm-up: what a
    user would otherwise run (here and in ``bench_nav.py``)."""
    from stable_baselines3 import DQN

    return DQN(
        "MlpPolicy",
        env,
        gamma=ours_cfg.gamma,
        learning_starts=ours_cfg.learning_starts,
        policy_kwargs={"net_arch": list(ours_cfg.hidden)},
        seed=seed,
        device="cpu",
        verbose=0,
    )


def run_sb3(ds, dyn, cfg, ours_cfg, threads) -> dict:
    try:
        from stable_baselines3.common.callbacks import BaseCallback
    except ImportError as e:
        return {"skipped": f"stable-baselines3 not installed ({e}); pip install 'dtradar[bench]'"}
    norm = Normalizer.fit(ds)
    env = DtradarNavEnv(ds, obs=ours_cfg.obs, reward=ours_cfg.reward, normalizer=norm)

    class Cap(BaseCallback):
        def __init__(self, seconds):
            super().__init__()
            self.seconds, self.t0 = seconds, time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < self.seconds

    torch.set_num_threads(threads)
    model = sb3_dqn(env, ours_cfg)
    t0 = time.perf_counter()
    model.learn(total_timesteps=cfg.budget, callback=Cap(cfg.sb3_max_seconds))
    wall = time.perf_counter() - t0
    steps = int(model.num_timesteps)
    policy = Policy(model.q_net.eval(), ours_cfg, norm, ours_cfg.obs, {"dataset": {"name": ds.name}})
    res = {
        "env_steps": steps,
        "wall_s": wall,
        "capped": steps < cfg.budget,
        "wall_s_for_budget": wall * cfg.budget / max(steps, 1),
        "settings": "SB3 DQN defaults (train_freq 4, batch 32, buffer 1M, eps 1 -> 0.05 over 10%), "
        f"net_arch {list(ours_cfg.hidden)}, gamma {ours_cfg.gamma}, "
        f"learning_starts {ours_cfg.learning_starts}, same observations and reward",
    }
    m, _ = evaluate(policy, ds, pairs=cfg.pairs, latency=False)
    res["blueprint"] = m.to_dict()
    if dyn is not None:
        m, _ = evaluate(policy, dyn, pairs=cfg.pairs, latency=False)
        res["dynamic"] = m.to_dict()
    return res


def train_preset(cfg, preset: str, folder: str, ds, dyn, threads: int, rows: list, *, label: str, shields=(False,)):
    """Train ``preset`` with the benchmark's budget, evaluate it on the blueprint and (each of ``shields``) the
    dynamic twin into ``rows``; its record for the report."""
    scene = ds.name.split("/")[0]
    pcfg = config_for(
        preset,
        scene=scene,
        total_env_steps=cfg.budget,
        out=f"{cfg.runs}/{scene}/{folder}",
        threads=threads,
        checkpoint_every=0,
    )
    result = train(pcfg, dataset=ds)
    policy = load_policy(result.checkpoint)
    m_bp, _ = evaluate(policy, ds, pairs=cfg.pairs, latency=False)
    rows.append({"case": f"ours ({label}): {ds.name} -> {ds.name}", **m_bp.to_dict()})
    for shield in shields if dyn is not None else ():
        m, _ = evaluate(policy, dyn, pairs=cfg.pairs, latency=False, shield=shield)
        rows.append({"case": f"ours ({label}): {ds.name} -> {dyn.name}" + " (shielded)" * shield, **m.to_dict()})
    print(f"{preset} DQN: {result.env_steps} env steps, {result.updates} updates in {result.wall_s:.1f} s")
    return {
        "config": pcfg.to_dict(),
        "env_steps": result.env_steps,
        "updates": result.updates,
        "wall_s": result.wall_s,
        "blueprint_success": m_bp.success_rate,
        "blueprint_spl": m_bp.spl,
    }


def _set_up_torch(cfg: BenchConfig) -> tuple[int, float | None]:
    """Torch's threads (``--threads`` or auto) and denormals flushed (slow on CPU); the thread count and the 1-min load
    before the start, which the report keeps since the shared machine's load moves every timing."""
    threads = cfg.threads or auto_threads()
    torch.set_num_threads(threads)
    torch.set_flush_denormal(True)
    load_before = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return threads, load_before


def _dataset_record(ds, synthetic: bool) -> dict:
    """The report's record of the twin benchmarked on (synthetic: the stand-in, not the scene asked for)."""
    return {"name": ds.name, "version": ds.version, "synthetic": synthetic, "grid": list(ds.shape)[::-1]}


def _machine_record(threads: int, load_before: float | None) -> dict:
    """The report's machine, taken when the report is made (after the runs: the load they were measured under)."""
    return {**machine(), "torch_threads": threads, "load_1min_before": load_before}


def _write_env_only(cfg: BenchConfig, out: Path, stem: str, ds, synthetic, threads, load_before, thr) -> dict:
    """``--env-only``: the throughput report alone, to ``<stem>_env.{json,md}``; the report."""
    report = {
        "dataset": _dataset_record(ds, synthetic),
        "machine": _machine_record(threads, load_before),
        "env_steps_per_s": thr,
    }
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / f"{stem}_env.json", json.dumps({"config": dataclasses.asdict(cfg), **report}, indent=2) + "\n")
    md = "\n".join(_header(report) + _throughput_rows(thr)) + "\n"
    write_atomic(out / f"{stem}_env.md", md)
    print(md)
    return report


def _train_tuned(cfg: BenchConfig, ds, dyn, threads: int):
    """The tuned DQN trained with the budget and evaluated (with decision latency, unlike the other presets: the
    report's latency is this agent's) on the blueprint and the dynamic twin, unshielded and shielded: its config, its
    training result, its blueprint metrics and the evaluation rows."""
    scene = ds.name.split("/")[0]
    ours_cfg = config_for(
        "tuned",
        scene=scene,
        total_env_steps=cfg.budget,
        out=f"{cfg.runs}/{scene}/dqn",
        threads=threads,
        checkpoint_every=0,
    )
    result = train(ours_cfg, dataset=ds)
    policy = load_policy(result.checkpoint)
    m_bp, _ = evaluate(policy, ds, pairs=cfg.pairs)
    rows = [{"case": f"ours (tuned): {ds.name} -> {ds.name}", **m_bp.to_dict()}]
    if dyn is not None:
        m_dyn, _ = evaluate(policy, dyn, pairs=cfg.pairs)
        rows.append({"case": f"ours (tuned): {ds.name} -> {dyn.name}", **m_dyn.to_dict()})
        m_sh, _ = evaluate(policy, dyn, pairs=cfg.pairs, shield=True)
        rows.append({"case": f"ours (tuned): {ds.name} -> {dyn.name} (shielded)", **m_sh.to_dict()})
    print(f"tuned DQN: {result.env_steps} env steps, {result.updates} updates in {result.wall_s:.1f} s")
    return ours_cfg, result, m_bp, rows


def _train_robust_and_default(cfg: BenchConfig, ds, dyn, threads: int, rows: list):
    """The robust and the default preset with the same budget, each unless switched off (``None`` then); their
    evaluations appended to ``rows``."""
    robust = (
        train_preset(
            cfg,
            "robust",
            "dqn_robust",
            ds,
            dyn,
            threads,
            rows,
            shields=(False, True),
            label=f"robust, {config_for('robust').aug_obstacles} extra obstacles",
        )
        if cfg.robust
        else None
    )
    default = (
        train_preset(cfg, DEFAULT_PRESET, "dqn_default", ds, dyn, threads, rows, label=f"default, {DEFAULT_PRESET}")
        if cfg.default
        else None
    )
    return robust, default


def _sb3_runs(cfg: BenchConfig, ds, dyn, ours_cfg, threads: int) -> tuple[dict, dict[int, dict]]:
    """SB3's DQN at each of ``--sb3-threads`` (or ours' threads): the run compared with (the fastest for the budget,
    so that SB3 is not judged at a thread count that does not suit it; the first run when none was timed) and every
    run by its thread count."""
    sb3: dict = {"skipped": "--no-sb3"}
    sb3_runs: dict[int, dict] = {}
    if cfg.sb3:
        for n in cfg.sb3_threads or (threads,):
            sb3_runs[n] = {**run_sb3(ds, dyn, cfg, ours_cfg, n), "threads": n}
            print(
                f"SB3 DQN, {n} torch thread(s): "
                f"{sb3_runs[n].get('wall_s_for_budget', float('nan')):.0f} s for the budget"
            )
        timed = [r for r in sb3_runs.values() if "wall_s_for_budget" in r]
        sb3 = min(timed, key=lambda r: r["wall_s_for_budget"]) if timed else next(iter(sb3_runs.values()))
    return sb3, sb3_runs


def _report(ds, synthetic, threads, load_before, thr, ours_cfg, result, m_bp, robust, default, rows, sb3, sb3_runs):
    """The report: throughput, decision latency, the tuned agent's training against the paper's and its goal, the
    other presets, every evaluation row and SB3's runs, with the speed-ups over SB3 where SB3 was timed."""
    report = {
        "dataset": _dataset_record(ds, synthetic),
        "machine": _machine_record(threads, load_before),
        "env_steps_per_s": thr,
        "batched_vs_gymnasium": {k: v / thr["gymnasium"] for k, v in thr.items() if k != "gymnasium"},
        "decision_latency_ms": m_bp.latency_ms,
        "paper_decision_ms": PAPER_DECISION_MS,
        "decision_speedup_vs_paper": PAPER_DECISION_MS / m_bp.latency_ms,
        "train": {
            "config": ours_cfg.to_dict(),
            "env_steps": result.env_steps,
            "updates": result.updates,
            "wall_s": result.wall_s,
            "paper_wall_s": PAPER_TRAIN_S,
            "speedup_vs_paper": PAPER_TRAIN_S / result.wall_s,
            "goal": "budget in <= 60 s with >= 95% success and SPL >= 0.9 on blueprint -> blueprint",
            "goal_met": bool(result.wall_s <= 60 and m_bp.success_rate >= 0.95 and m_bp.spl >= 0.9),
        },
        "train_robust": robust,
        "train_default": default,
        "eval": rows,
        "sb3": sb3,
        "sb3_by_threads": {
            str(n): {k: r[k] for k in ("wall_s", "env_steps", "wall_s_for_budget") if k in r}
            for n, r in sb3_runs.items()
        },
    }
    if "wall_s_for_budget" in sb3:
        report["train"]["speedup_vs_sb3"] = sb3["wall_s_for_budget"] / result.wall_s
        if default is not None:
            default["speedup_vs_sb3"] = sb3["wall_s_for_budget"] / default["wall_s"]
    return report


def main(cfg: BenchConfig) -> dict:
    """Set up, measure the env, train and time each side (ours, the other presets, SB3), write JSON + Markdown."""
    threads, load_before = _set_up_torch(cfg)
    ds, dyn, synthetic = _datasets(cfg.scene)
    print(
        f"dataset: {ds.name} ({'synthetic stand-in' if synthetic else 'real'}), grid {ds.shape[1]}x{ds.shape[0]}, "
        f"torch threads {threads}, 1-min load before start {load_before}"
    )

    thr = env_throughput(
        ds, cfg.env_counts, cfg.env_seconds, rounds=cfg.env_rounds, general=cfg.env_general, threads=cfg.env_threads
    )
    print("env steps/s:", {k: f"{v:,.0f}" for k, v in thr.items()})
    stem = cfg.name or ("bench_rl" if cfg.scene == "cubicle" else f"bench_rl_{cfg.scene}")
    out = Path(cfg.out)
    if cfg.env_only:
        return _write_env_only(cfg, out, stem, ds, synthetic, threads, load_before, thr)

    ours_cfg, result, m_bp, rows = _train_tuned(cfg, ds, dyn, threads)
    robust, default = _train_robust_and_default(cfg, ds, dyn, threads, rows)
    sb3, sb3_runs = _sb3_runs(cfg, ds, dyn, ours_cfg, threads)
    scene = ds.name.split("/")[0]
    for twin in ("blueprint", "dynamic"):
        if twin in sb3:
            rows.append({"case": f"SB3 DQN: {ds.name} -> {scene}/{twin}", **sb3[twin], "latency_ms": None})
    report = _report(
        ds, synthetic, threads, load_before, thr, ours_cfg, result, m_bp, robust, default, rows, sb3, sb3_runs
    )

    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / f"{stem}.json", json.dumps({"config": dataclasses.asdict(cfg), **report}, indent=2) + "\n")
    md = render_markdown(report)
    write_atomic(out / f"{stem}.md", md)
    print(md)
    return report


if __name__ == "__main__":
    main(tyro.cli(BenchConfig, args=sys.argv[1:]))
