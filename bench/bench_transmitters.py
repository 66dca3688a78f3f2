"""Tracing time and memory per transmitter, side by side in one run: a twin with its first K transmitters, K = 1..N.

A twin with several transmitters is traced in one pass (Sionna's solver shoots ``samples_per_src`` rays from each),
so time and the candidate-path buffer grow with K. For each K of ``--counts`` the scene's blueprint keeps its first K
transmitters and its whole free grid is traced in a fresh process (a warm kernel first, so the timing is the trace,
not the JIT compile; the peak resident memory is that process's). Transmitter 0's columns must be identical for
every K: adding a transmitter must not change what the others trace. Writes ``results/bench_transmitters.json``,
``.md`` and ``.png`` (seconds and GiB against K, and the ratio to K = 1).

    python bench/bench_transmitters.py [--scene dallas-3tx-q3] [--counts 1 2 3]
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import multiprocessing as mp
import resource
import time
from pathlib import Path

import numpy as np


def _trace(scene: str, k: int, out) -> None:
    """One process: the scene with its first ``k`` transmitters, traced whole; seconds, peak RSS, tx0's hash."""
    from dtradar_data.core.schema import CELL_SCHEMA, tx_column
    from dtradar_data.geometry.occupancy import occupancy
    from dtradar_data.geometry.xml_meshes import ground_height
    from dtradar_data.pipeline.config import BuildConfig, scene_config
    from dtradar_data.pipeline.tracing import trace_grid
    from dtradar_data.rt.tracer import RayTracer
    from dtradar_data.scenes import load_scene_spec

    spec = load_scene_spec(scene, "blueprint")
    spec = dataclasses.replace(spec, more_tx=spec.more_tx[: k - 1])
    settings = scene_config(BuildConfig(scene=scene), spec).rt
    tracer = RayTracer(spec, settings)
    xs, ys = spec.grid.centres()
    iy, ix = np.nonzero(~occupancy(spec))
    warm = np.stack([xs[ix[:4]], ys[iy[:4]], spec.rx_height_m + ground_height(spec, xs[ix[:4]], ys[iy[:4]])], 1)
    tracer.trace_each(warm)  # the kernels compiled first: the timing is the trace
    t0 = time.perf_counter()
    cells, _, blocked, tracer = trace_grid(spec, settings, None, per_path=False, progress=False, tracer=tracer)
    seconds = time.perf_counter() - t0
    tracer.close()
    tx0 = CELL_SCHEMA.names  # transmitter 0's columns are the one-transmitter table's
    digest = hashlib.sha256(b"".join(cells.column(c).to_numpy(zero_copy_only=False).tobytes() for c in tx0))
    heard = np.zeros(len(cells), bool)
    for j in range(k):
        heard |= cells.column(tx_column("num_paths", j)).to_numpy() > 0
    free = ~blocked.ravel()
    out.put(
        {
            "transmitters": k,
            "seconds": round(seconds, 2),
            "peak_rss_gib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 2),
            "free_cells": int(free.sum()),
            "heard": int((heard & free).sum()),
            "tx0_sha256": digest.hexdigest()[:16],
        }
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="dallas-3tx-q3")
    p.add_argument("--counts", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--out", type=Path, default=Path("results"))
    a = p.parse_args(argv)
    from dtradar_data.core.machine import describe, machine
    from dtradar_data.scenes import load_scene_spec

    have = len(load_scene_spec(a.scene, "blueprint").transmitters)
    if max(a.counts) > have or min(a.counts) < 1:
        p.error(f"{a.scene} has {have} transmitter(s): --counts must lie in 1..{have}")
    rows = []
    ctx = mp.get_context("spawn")
    for k in a.counts:
        q = ctx.Queue()
        proc = ctx.Process(target=_trace, args=(a.scene, k, q))
        proc.start()
        rows.append(q.get())
        proc.join()
        print(rows[-1], flush=True)
    base = rows[0]["seconds"]
    for r in rows:
        r["seconds_ratio"] = round(r["seconds"] / base, 2)
        r["seconds_per_transmitter"] = round(r["seconds"] / r["transmitters"], 2)
    same = len({r["tx0_sha256"] for r in rows}) == 1
    a.out.mkdir(parents=True, exist_ok=True)
    report = {"scene": a.scene, "machine": machine(), "rows": rows, "tx0_identical_for_every_count": same}
    (a.out / "bench_transmitters.json").write_text(json.dumps(report, indent=2) + "\n")
    lines = [
        f"# Tracing time per transmitter: {a.scene}",
        "",
        f"Machine: {describe()}. Command: `python bench/bench_transmitters.py --scene {a.scene} --counts "
        + " ".join(map(str, a.counts))
        + "`.",
        "",
        "| transmitters | trace (s) | x K = 1 | s per transmitter | peak RSS (GiB) | free cells heard |",
        "|---:|---:|---:|---:|---:|---:|",
        *(
            f"| {r['transmitters']} | {r['seconds']} | {r['seconds_ratio']} | {r['seconds_per_transmitter']} | "
            f"{r['peak_rss_gib']} | {r['heard']} of {r['free_cells']} |"
            for r in rows
        ),
        "",
        f"Transmitter 0's columns identical for every count: {'yes' if same else 'NO'}.",
    ]
    (a.out / "bench_transmitters.md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.5))
    ks = [r["transmitters"] for r in rows]
    ax1.plot(ks, [r["seconds"] for r in rows], "o-")
    ax1.set(xlabel="transmitters", ylabel="trace seconds", title=a.scene)
    ax2.plot(ks, [r["peak_rss_gib"] for r in rows], "o-", color="tab:red")
    ax2.set(xlabel="transmitters", ylabel="peak RSS (GiB)")
    fig.tight_layout()
    fig.savefig(a.out / "bench_transmitters.png", dpi=120)
    print("\n".join(lines))
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
