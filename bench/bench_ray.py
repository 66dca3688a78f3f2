"""Serial vs Ray ray tracing, side by side in one run: cells/s, the speed-up, and a projection to N machines.

For each scene, the whole free grid is traced twice into fresh work folders: once by the serial executor (this
process, one tracing thread), once by Ray workers on all cores (a local Ray started for the run; its start-up and
each worker's scene build and JIT compile are included, as a user pays them). Both tables must be identical. The
projection for N machines multiplies the measured per-worker rate by the workers, ignoring start-up and network.
Results go to ``results/bench_ray.json`` and ``results/bench_ray.md``.

    python bench/bench_ray.py [--scenes cubicle dallas-q3] [--cubicle-batch 128] [--workers 0]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from dtradar_data.core.machine import describe, machine
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline.builder import BuildConfig, scene_config, trace_grid
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store.versions import library_versions


def timed(spec, settings, executor: str, workers: int):
    with tempfile.TemporaryDirectory(prefix="dtradar-bench-ray-") as work:
        t0 = time.perf_counter()
        cells, _, _, tracer = trace_grid(
            spec, settings, Path(work), per_path=True, progress=False, executor=executor, workers=workers
        )
        seconds = time.perf_counter() - t0
    if tracer is not None:
        tracer.close()
    return cells, seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", nargs="+", default=["cubicle", "dallas-q3"])
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
        "--batch-independent",
        action="store_true",
        help="trace with RTSettings.batch_independent: small batches then change no row, so they can balance workers",
    )
    ap.add_argument("--workers", type=int, default=0, help="Ray workers (0 = one per core)")
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()
    import ray

    workers = args.workers or os.cpu_count() or 1
    rows = []
    for scene in args.scenes:
        spec = load_scene_spec(scene, "blueprint")
        cfg = scene_config(BuildConfig(scene=scene), spec)
        settings = cfg.rt if spec.prisms or spec.base else replace(cfg.rt, batch_size=args.cubicle_batch)
        if (spec.prisms or spec.base) and args.city_batch:
            settings = replace(settings, batch_size=args.city_batch)
        if args.batch_independent:
            settings = replace(settings, batch_independent=True)
        free = int((~occupancy(spec)).sum())
        batches = -(-free // settings.batch_size)
        print(
            f"{spec.name}: {free} free cells in {batches} batches of {settings.batch_size}, "
            f"{settings.samples_per_src:.0e} rays, buffer {settings.max_num_paths_per_src:.0e}"
        )
        serial, serial_s = timed(spec, settings, "serial", 0)
        print(f"  serial: {serial_s:.1f} s ({free / serial_s:.1f} cells/s)")
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            on_ray, ray_s = timed(spec, settings, "ray", workers)
        finally:
            ray.shutdown()
        used = min(workers, batches)
        print(f"  ray ({used} workers): {ray_s:.1f} s ({free / ray_s:.1f} cells/s), speed-up {serial_s / ray_s:.2f}x")
        rows.append(
            {
                "scene": spec.name,
                "free_cells": free,
                "batch_size": settings.batch_size,
                "batches": batches,
                "samples_per_src": settings.samples_per_src,
                "max_num_paths_per_src": settings.max_num_paths_per_src,
                "serial_s": round(serial_s, 2),
                "serial_cells_per_s": round(free / serial_s, 1),
                "ray_workers": used,
                "ray_s": round(ray_s, 2),
                "ray_cells_per_s": round(free / ray_s, 1),
                "speedup": round(serial_s / ray_s, 2),
                "identical_tables": bool(on_ray.equals(serial)),
                "per_worker_cells_per_s": round(free / ray_s / used, 1),
            }
        )
    host = machine()
    described = f"{describe(host)}, no GPU (LLVM backend)"
    load = host["load_average"][0] if host["load_average"] else None
    result = {
        "machine": described,
        "load_average_at_end": load,
        "machine_details": host,
        "rows": rows,
        "library_versions": library_versions(),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench_ray.json").write_text(json.dumps(result, indent=2) + "\n")
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
    (args.out / "bench_ray.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    assert all(r["identical_tables"] for r in rows), "Ray and serial tables differ"


if __name__ == "__main__":
    main()
