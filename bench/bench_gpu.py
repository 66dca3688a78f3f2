"""GPU figures, side by side with the CPU in one run: tracing a twin, the batched env and a training run.

    python bench/bench_gpu.py                      # `make bench-gpu`: CUDA beside this machine's CPU
    python bench/bench_gpu.py --device cpu --trace-cells 64 --env-counts 256 --train-steps 20000   # a dry run, no GPU
    bash bench/gpu.sh                              # on a lent GPU machine: venv, twins, this script, one JSON

Three sections, each measured on ``--device`` (default ``cuda``) and on the CPU in the same run:

1. **Tracing** ``<scene>/<variant>`` (default the Dallas Q3 blueprint) with the settings it was built with (read from
   its card), on ``--trace-cells`` free cells (0 = all): cells/s on Dr.Jit's CUDA backend and on its LLVM (CPU)
   backend, each warm (the first call, JIT included, reported apart), and the strongest-path agreement of the CUDA
   rows with the CPU rows beside the seed-noise floor (two CPU traces with different seeds), as ``make bench-rt``
   compares. Each backend traces in its own process: Mitsuba's variant is chosen once per process.
2. **The batched env**: env steps/s of random moves at ``--env-counts`` robots, as ``make bench-rl`` measures.
3. **Training**: the default DQN preset for ``--train-steps`` env steps on ``<train-scene>/blueprint`` (default the
   cubicle), wall time and the greedy success / SPL on its blueprint and dynamic twins (500 pairs, seed 2024).

Writes ``results/bench_gpu.json`` and ``results/bench_gpu.md`` (``--out``), with the machine and the torch / Dr.Jit
devices named. Nothing here is measured on this project's 2-core machine: it has no GPU.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import platform
import time
from pathlib import Path

import numpy as np


def _trace(scene: str, variant: str, device: str, cells: int, seed: int | None, queue) -> None:
    """Trace ``cells`` free cells of the twin on ``device`` (a fresh process: one Mitsuba variant per process)."""
    try:
        from dataclasses import replace

        from dtradar_data import load
        from dtradar_data.rt import features
        from dtradar_data.rt.settings import RTSettings
        from dtradar_data.rt.tracer import RayTracer
        from dtradar_data.scenes import load_scene_spec

        ds = load(f"{scene}/{variant}")
        known = {f for f in RTSettings.__dataclass_fields__}
        built = {k: v for k, v in (ds.meta.get("rt") or {}).items() if k in known}
        # Sionna's own solver on both devices: the batch-independent one exists for the CPU only, and the comparison
        # must trace the same way on both (a twin's meta records the engine as a string, not the flag)
        settings = RTSettings(**{**built, "device": device, "batch_independent": False})
        if seed is not None:
            settings = replace(settings, seed=seed)
        spec = load_scene_spec(scene, variant)
        from dtradar_data.geometry.occupancy import occupancy

        blocked = occupancy(spec)
        xs, ys = spec.grid.centres()
        iy, ix = np.nonzero(~blocked)
        points = np.stack([xs[ix], ys[iy], np.full(ix.shape, spec.rx_height_m)], axis=1)
        if cells:
            points = points[np.linspace(0, len(points) - 1, min(cells, len(points))).astype(int)]
        tracer = RayTracer(spec, settings)
        t0 = time.perf_counter()
        tracer.trace(points[: min(len(points), 8)])
        first_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        gains, strongest = [], []
        for s in range(0, len(points), settings.batch_size):
            b = tracer.trace(points[s : s + settings.batch_size])
            cells_ = features.reduce_cells(b)
            gains.append(np.asarray(cells_["path_gain_db"], float))
            n = b.num_receivers
            rows = features.path_rows(b, np.arange(n), np.zeros(n))
            first = rows["path"] == 0
            key = np.full(n, "", dtype=object)
            key[rows["ix"][first]] = [
                f"{i}|{t * 1e9:.1f}" for i, t in zip(rows["interactions"][first], rows["tau_s"][first])
            ]
            strongest.append(key)
        dt = time.perf_counter() - t0
        queue.put(
            {
                "device": device,
                "cells": int(len(points)),
                "seconds": dt,
                "cells_per_s": len(points) / dt,
                "first_call_s": first_s,
                "settings": settings.hashed(),
                "gain_db": np.concatenate(gains).tolist(),
                "strongest": np.concatenate(strongest).tolist(),
            }
        )
    except Exception as e:  # reported in the JSON, the other sections still run
        queue.put({"device": device, "error": f"{type(e).__name__}: {e}"})


def trace_in_process(scene, variant, device, cells, seed=None) -> dict:
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    p = ctx.Process(target=_trace, args=(scene, variant, device, cells, seed, q))
    p.start()
    out = q.get()
    p.join()
    return out


def agreement(a: dict, b: dict) -> float:
    """Share of cells whose strongest path (interactions, delay to 0.1 ns) is the same in both traces."""
    return float(np.mean(np.asarray(a["strongest"], object) == np.asarray(b["strongest"], object)))


def env_rates(ds, counts, device: str, seconds: float) -> dict[str, float]:
    import torch

    from dtradar_rl.envs.batched import BatchedNavEnv

    out = {}
    for k in counts:
        env = BatchedNavEnv.from_dataset(ds, k, obs="neighbors", reward="geodesic", seed=0, device=device)
        env.reset()
        gen = torch.Generator(device=device).manual_seed(0)
        for _ in range(20):  # warm-up (CUDA kernels, caches)
            env.step(torch.randint(4, (k,), generator=gen, device=device))
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        steps, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            _, _, te, tr, _ = env.step(torch.randint(4, (k,), generator=gen, device=device))
            env.reset_where(te | tr)
            env.observe()
            steps += k
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        out[str(k)] = steps / (time.perf_counter() - t0)
    return out


def train_once(scene: str, device: str, steps: int, out: Path) -> dict:
    from dtradar_rl.evaluation.evaluate import evaluate
    from dtradar_rl.task.twins import load_dataset
    from dtradar_rl.train.config import config_for
    from dtradar_rl.train.dqn import train
    from dtradar_rl.train.saved_runs import load_policy

    cfg = config_for(scene=scene, total_env_steps=steps, device=device, out=str(out), verbose=False)
    t0 = time.perf_counter()
    r = train(cfg)
    wall = time.perf_counter() - t0
    policy = load_policy(r.checkpoint, device)
    row = {"device": device, "env_steps": r.env_steps, "updates": r.updates, "wall_s": wall}
    for v in ("blueprint", "dynamic"):
        try:
            m, _ = evaluate(policy, load_dataset(f"{scene}/{v}"), pairs=500, seed=2024, latency=False, device=device)
            row[v] = {"success_rate": m.success_rate, "spl": m.spl}
        except Exception as e:
            row[v] = {"error": f"{type(e).__name__}: {e}"}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--device", default="cuda", help="the accelerator's torch / Dr.Jit device (cuda or cpu)")
    ap.add_argument("--scene", default="dallas-q3", help="twin traced in section 1")
    ap.add_argument("--variant", default="blueprint")
    ap.add_argument("--trace-cells", type=int, default=0, help="free cells traced (0 = all)")
    ap.add_argument("--cpu-trace-cells", type=int, default=256, help="cells the CPU traces (its rate, agreement)")
    ap.add_argument("--env-counts", type=int, nargs="+", default=[4096, 65536])
    ap.add_argument("--env-seconds", type=float, default=3.0)
    ap.add_argument("--train-scene", default="cubicle")
    ap.add_argument("--train-steps", type=int, default=600_000)
    ap.add_argument("--sections", nargs="+", default=["trace", "env", "train"], choices=["trace", "env", "train"])
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    import torch

    result: dict = {
        "argv": vars(args) | {"out": str(args.out)},
        "machine": {
            "platform": platform.platform(),
            "cpus": mp.cpu_count(),
            "torch": torch.__version__,
            "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
        },
    }

    def save() -> None:
        (args.out / "bench_gpu.json").write_text(json.dumps(result, indent=2) + "\n")

    if "trace" in args.sections:
        # the CPU rows first, on a subset that keeps the run short; the device traces those same cells too (the
        # subset is spread evenly, so cells=N picks the same cells in every process)
        cpu = trace_in_process(args.scene, args.variant, "cpu", args.cpu_trace_cells)
        floor = trace_in_process(args.scene, args.variant, "cpu", args.cpu_trace_cells, seed=7)
        dev_same = trace_in_process(args.scene, args.variant, args.device, args.cpu_trace_cells)
        dev_all = trace_in_process(args.scene, args.variant, args.device, args.trace_cells)
        sec = {"cpu": _brief(cpu), "device_subset": _brief(dev_same), "device": _brief(dev_all)}
        if all("error" not in x for x in (cpu, floor, dev_same)):
            sec["agreement_device_vs_cpu"] = agreement(dev_same, cpu)
            sec["noise_floor_cpu_seed_42_vs_7"] = agreement(floor, cpu)
            sec["speedup_cells_per_s"] = dev_all.get("cells_per_s", float("nan")) / cpu["cells_per_s"]
        result["trace"] = sec
        save()
    if "env" in args.sections:
        from dtradar_rl.task.twins import load_dataset

        ds = load_dataset(f"{args.train_scene}/blueprint")
        result["env_steps_per_s"] = {
            "cpu": env_rates(ds, args.env_counts, "cpu", args.env_seconds),
            args.device: env_rates(ds, args.env_counts, args.device, args.env_seconds),
        }
        save()
    if "train" in args.sections:
        result["train"] = [
            train_once(args.train_scene, d, args.train_steps, args.out / f"bench_gpu_train_{d}")
            for d in dict.fromkeys([args.device, "cpu"])
        ]
        save()
    (args.out / "bench_gpu.md").write_text(markdown(result))
    print(markdown(result))


def _brief(t: dict) -> dict:
    return {k: v for k, v in t.items() if k not in ("gain_db", "strongest")}


def markdown(r: dict) -> str:
    m = r["machine"]
    lines = [f"# GPU figures: {m.get('cuda') or 'no CUDA device'} ({m['cpus']} CPUs, {m['platform']})", ""]
    if "trace" in r:
        t = r["trace"]
        lines += ["## Tracing", "", "| backend | cells | cells/s | first call (s) |", "|---|---:|---:|---:|"]
        for k in ("cpu", "device_subset", "device"):
            x = t[k]
            if "error" in x:
                lines.append(f"| {k} | error: {x['error']} | | |")
            else:
                rate, first = f"{x['cells_per_s']:.1f}", f"{x['first_call_s']:.1f}"
                lines.append(f"| {k} ({x['device']}) | {x['cells']} | {rate} | {first} |")
        if "agreement_device_vs_cpu" in t:
            lines += [
                "",
                f"Strongest-path agreement, device vs CPU: {100 * t['agreement_device_vs_cpu']:.1f} % "
                f"(noise floor, CPU seed 42 vs 7: {100 * t['noise_floor_cpu_seed_42_vs_7']:.1f} %); "
                f"speed-up {t['speedup_cells_per_s']:.1f}x.",
            ]
        lines.append("")
    if "env_steps_per_s" in r:
        e = r["env_steps_per_s"]
        devs = list(e)
        lines += ["## Batched env (env steps/s)", "", "| robots | " + " | ".join(devs) + " |"]
        lines.append("|---:|" + "---:|" * len(devs))
        for k in next(iter(e.values())):
            lines.append(f"| {k} | " + " | ".join(f"{e[d][k] / 1e6:.1f} M" for d in devs) + " |")
        lines.append("")
    if "train" in r:
        lines += ["## Training (default preset)", "", "| device | env steps | wall (s) | blueprint | dynamic |"]
        lines.append("|---|---:|---:|---|---|")
        for row in r["train"]:
            cells = [
                f"{row[v]['success_rate']:.3f} / {row[v]['spl']:.3f}" if "spl" in row[v] else row[v].get("error", "")
                for v in ("blueprint", "dynamic")
            ]
            lines.append(f"| {row['device']} | {row['env_steps']} | {row['wall_s']:.1f} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
