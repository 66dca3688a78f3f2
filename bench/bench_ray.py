"""Serial vs Ray ray tracing, side by side in one run: cells/s, the speed-up, and a projection to N machines.

For each entry of ``--scenes`` the whole free grid of its blueprint(s) is traced twice into fresh work folders: once
by the serial executor (this process, one tracing thread), once by Ray workers on all cores in one
:class:`~dtradar_data.pipeline.executors.RaySession`, as ``build --executor ray`` runs (Ray's start-up, each worker's
start and each scene build and JIT compile are included, as a user pays them). A city name (``dallas``) is all its
quadrants in one build, so the workers stay warm from one quadrant to the next. Every table must be identical. The
projection for N machines multiplies the measured per-worker rate by the workers, ignoring start-up and network.
Results go to ``results/bench_ray.json`` and ``results/bench_ray.md``.

    python bench/bench_ray.py [--scenes cubicle dallas-q3 dallas] [--cubicle-batch 128] [--workers 0]
                              [--stock-solver] [--city-batch 0]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from dtradar_data.core.machine import describe, machine
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline.batches import batch_layout
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.executors import RaySession
from dtradar_data.pipeline.tracing import trace_grid
from dtradar_data.scenes import build_targets, load_scene_spec
from dtradar_data.store.versions import library_versions


def timed(jobs, executor: str, workers: int):
    """Trace every ``(spec, settings)`` of ``jobs`` as one build does; the tables and the seconds it took."""
    tables = []
    with tempfile.TemporaryDirectory(prefix="dtradar-bench-ray-") as work:
        t0 = time.perf_counter()
        with RaySession(None, workers) if executor == "ray" else contextlib.nullcontext():
            for k, (spec, settings) in enumerate(jobs):
                cells, _, _, tracer = trace_grid(
                    spec,
                    settings,
                    Path(work) / str(k),
                    per_path=True,
                    progress=False,
                    executor=executor,
                    workers=workers,
                )
                if tracer is not None:
                    tracer.close()
                tables.append(cells)
        seconds = time.perf_counter() - t0
    return tables, seconds


def _tracer_process(scene: str, settings, cells: int, barrier, out) -> None:
    """One tracer process of :func:`contention`: the scene built and warmed first, then ``cells`` cells timed."""
    import numpy as np

    from dtradar_data.rt.tracer import RayTracer

    spec = load_scene_spec(scene, "blueprint")
    xs, ys = spec.grid.centres()
    iy, ix = np.nonzero(~occupancy(spec))
    points = np.stack([xs[ix], ys[iy], np.full(len(ix), spec.rx_height_m)], axis=1)
    tracer = RayTracer(spec, settings)
    tracer.trace(points[:4])  # scene build and kernel compile out of the timing
    barrier.wait()
    t0 = time.perf_counter()
    tracer.trace(points[:cells])
    out.put(time.perf_counter() - t0)


def contention(scene: str, settings, workers: int, cells: int = 400) -> dict:
    """What this machine itself allows ``workers`` tracers, without Ray: the same call timed in one process alone,
    then in ``workers`` processes at once (started together; scene builds not timed). The ceiling of any executor is
    ``workers * alone / together``."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    seconds = {}
    for n in (1, workers):
        barrier, out = ctx.Barrier(n), ctx.Queue()
        procs = [ctx.Process(target=_tracer_process, args=(scene, settings, cells, barrier, out)) for _ in range(n)]
        for proc in procs:
            proc.start()
        times = [out.get() for _ in procs]
        for proc in procs:
            proc.join()
        seconds[n] = max(times)
    return {
        "scene": scene,
        "cells": cells,
        "alone_s": round(seconds[1], 2),
        "together_s": round(seconds[workers], 2),
        "processes": workers,
        "ceiling_speedup": round(workers * seconds[1] / seconds[workers], 2),
    }


def settings_for(spec, args):
    cfg = scene_config(BuildConfig(scene=spec.scene), spec)
    city = bool(spec.prisms or spec.base)
    settings = cfg.rt if city else replace(cfg.rt, batch_size=args.cubicle_batch)
    if city and args.city_batch:
        settings = replace(settings, batch_size=args.city_batch)
    if args.stock_solver:
        settings = replace(settings, batch_independent=False)
    return settings


def main() -> None:
    args = _parser().parse_args()
    workers = args.workers or os.cpu_count() or 1
    rows = [_measured(entry, args, workers) for entry in args.scenes]
    ceiling = _ceiling(args, workers)
    host = machine()
    described = f"{describe(host)}, no GPU (LLVM backend)"
    load = host["load_average"][0] if host["load_average"] else None
    result = {
        "machine": described,
        "load_average_at_end": load,
        "machine_details": host,
        "rows": rows,
        "ceiling": ceiling,
        "library_versions": library_versions(),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench_ray.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = _report(rows, ceiling, workers, described)
    (args.out / "bench_ray.md").write_text("\n".join(lines) + "\n")
    if rows:
        plot(rows, workers, args.out / "bench_ray.png", described)
    print("\n".join(lines))
    assert all(r["identical_tables"] for r in rows), "Ray and serial tables differ"


def _parser() -> argparse.ArgumentParser:
    """The options; ``--help`` shows the docstring's first paragraph only."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="*", default=["cubicle", "dallas-q3"])
    ap.add_argument(
        "--cubicle-batch",
        type=int,
        default=128,
        help="batch size of the indoor scenes: the default 1024 is one batch for the cubicle, which "
        "cannot be split over workers",
    )
    ap.add_argument(
        "--city-batch", type=int, default=0, help="batch size of the city scenes (0 = their settings' 1024)"
    )
    ap.add_argument(
        "--stock-solver",
        action="store_true",
        help="trace with Sionna's own PathSolver (--rt.no-batch-independent): the batch partition then changes rows, "
        "so the batches cannot be evened out",
    )
    ap.add_argument("--workers", type=int, default=0, help="Ray workers (0 = one per core)")
    ap.add_argument(
        "--contention",
        default="dallas-q3",
        help="scene of the machine's own ceiling: one tracer alone vs one per worker at once, no Ray ('' = skip)",
    )
    ap.add_argument("--out", type=Path, default=Path("results"))
    return ap


def _measured(entry: str, args, workers: int) -> dict:
    """One ``--scenes`` entry (a city: all its quadrants) traced serially, then on Ray; its row of the table."""
    specs = [load_scene_spec(scene, "blueprint") for scene, _ in build_targets(entry, "blueprint")]
    jobs = [(spec, settings_for(spec, args)) for spec in specs]
    free = sum(int((~occupancy(spec)).sum()) for spec in specs)
    layouts = [(int((~occupancy(s)).sum()), batch_layout(int((~occupancy(s)).sum()), st)) for s, st in jobs]
    batches = sum(-(-n // size) for n, size in layouts)
    settings = jobs[0][1]
    name = entry if len(specs) > 1 else specs[0].name
    print(
        f"{name}: {len(specs)} scene(s), {free} free cells in {batches} batches "
        f"({', '.join(str(size) for _, size in layouts)} cells each), {settings.samples_per_src:.0e} rays, "
        f"buffer {settings.max_num_paths_per_src:.0e}"
        + (", Sionna's own solver" if args.stock_solver else ", batch-independent")
    )
    serial, serial_s = timed(jobs, "serial", 0)
    print(f"  serial: {serial_s:.1f} s ({free / serial_s:.1f} cells/s)")
    on_ray, ray_s = timed(jobs, "ray", workers)
    # no more workers can be busy than the scene with the most batches has batches
    used = min(workers, max(-(-n // size) for n, size in layouts))
    print(f"  ray ({used} workers): {ray_s:.1f} s ({free / ray_s:.1f} cells/s), speed-up {serial_s / ray_s:.2f}x")
    return {
        "scene": name,
        "scenes": [s.name for s in specs],
        "free_cells": free,
        "batch_size": settings.batch_size,
        "cells_per_batch": [size for _, size in layouts],
        "batch_independent": not args.stock_solver,
        "batches": batches,
        "samples_per_src": settings.samples_per_src,
        "max_num_paths_per_src": settings.max_num_paths_per_src,
        "serial_s": round(serial_s, 2),
        "serial_cells_per_s": round(free / serial_s, 1),
        "ray_workers": used,
        "ray_s": round(ray_s, 2),
        "ray_cells_per_s": round(free / ray_s, 1),
        "speedup": round(serial_s / ray_s, 2),
        "identical_tables": all(a.equals(b) for a, b in zip(on_ray, serial)),
        "per_worker_cells_per_s": round(free / ray_s / used, 1),
    }


def _ceiling(args, workers: int) -> dict | None:
    """The machine's own ceiling on ``--contention`` (None when it is ''), printed."""
    if not args.contention:
        return None
    spec = load_scene_spec(args.contention, "blueprint")
    ceiling = contention(args.contention, settings_for(spec, args), workers)
    print(
        f"ceiling: {ceiling['cells']} cells of {args.contention} in {ceiling['alone_s']} s alone, "
        f"{ceiling['together_s']} s with {workers} at once: at most {ceiling['ceiling_speedup']}x on this machine"
    )
    return ceiling


def _report(rows: list[dict], ceiling: dict | None, workers: int, described: str) -> list[str]:
    """The Markdown lines: one row an entry, with the projection to 4 and 16 machines, then the ceiling."""
    lines = [
        f"# Serial vs Ray tracing ({described})",
        "",
        "| dataset | free cells | batches | serial cells/s | Ray workers | Ray cells/s | speed-up | identical | "
        "projected cells/s on 4 / 16 machines of this kind |",
        "|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in rows:
        per_machine = r["per_worker_cells_per_s"] * workers
        lines.append(
            f"| {r['scene']} | {r['free_cells']} | {r['batches']} | {r['serial_cells_per_s']} | "
            f"{r['ray_workers']} | {r['ray_cells_per_s']} | {r['speedup']}× | {r['identical_tables']} | "
            f"{4 * per_machine:.0f} / {16 * per_machine:.0f} |"
        )
    if ceiling:
        lines += [
            "",
            f"The machine's own ceiling (no Ray): {ceiling['cells']} cells of {ceiling['scene']} traced in "
            f"{ceiling['alone_s']} s by one process alone, {ceiling['together_s']} s by each of {workers} at once: "
            f"at most {ceiling['ceiling_speedup']}× on {workers} workers before any start-up.",
        ]
    return lines


def plot(rows, workers: int, path: Path, described: str) -> None:
    """Serial and Ray cells/s of each entry side by side, the speed-up written over Ray's bar."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.8 + 1.6 * len(rows), 3.6))
    x = range(len(rows))
    ax.bar([i - 0.2 for i in x], [r["serial_cells_per_s"] for r in rows], 0.4, label="serial (1 thread)")
    ax.bar([i + 0.2 for i in x], [r["ray_cells_per_s"] for r in rows], 0.4, label=f"Ray ({workers} workers)")
    for i, r in zip(x, rows):
        ax.annotate(f"{r['speedup']}x", (i + 0.2, r["ray_cells_per_s"]), ha="center", va="bottom", fontsize=9)
    ax.set_xticks(list(x), [r["scene"] for r in rows])
    ax.set_ylabel("cells / s (start-up included)")
    ax.set_title(described, fontsize=8)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
