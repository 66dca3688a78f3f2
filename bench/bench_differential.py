"""Differential re-tracing against a full re-trace of the same changed twin, side by side in one run.

For each scene: load the newest stored blueprint (the parent), then trace the dynamic twin twice, warm (a few cells
are traced first so neither run pays the JIT compile): in full, and differentially (only the cells the changed
objects can affect, :mod:`dtradar_data.pipeline.differential`; the parent's other rows kept). Reported: cells
re-traced, both trace times and their ratio, the strongest-path agreement (:mod:`dtradar_data.rt.compare`) of the
differential twin with the full one (overall, in the re-traced cells, in the kept ones) and the absolute total-gain
differences; as a noise floor, the same agreement for the parent reused unchanged and (``--seed-floor``) for a
second full trace with another ray-sampling seed. Writes ``results/bench_differential_<scene>.{json,md,png}``.

    python bench/bench_differential.py --scenes cubicle meeting dallas-q3   # needs their blueprints built
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import write_atomic
from dtradar_data.core.machine import describe, machine
from dtradar_data.pipeline import differential
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.parent import differential_parent
from dtradar_data.pipeline.tracing import trace_grid
from dtradar_data.rt.compare import compare
from dtradar_data.rt.compare import summarize as stats
from dtradar_data.rt.tracer import RayTracer
from dtradar_data.scenes import load_scene_spec


def as_dataset(name: str, parent: Dataset, cells, paths) -> Dataset:
    return Dataset(name=name, table=cells, meta={"grid": parent.meta["grid"]}, paths_table=paths)


def bench_scene(scene: str, radius_m: float, seed_floor: bool, out: Path) -> dict:
    spec = load_scene_spec(scene, "dynamic")
    config = scene_config(BuildConfig(scene=scene, progress=False), spec)
    parent, parent_spec = differential_parent(spec, config)
    rt = config.rt
    # warm-up: load the scene and compile the kernels on a few cells, so neither timed run pays for it
    warm = RayTracer(spec, rt)
    xs, ys = spec.grid.centres()
    warm.trace(np.stack([xs[:4], np.full(4, ys[len(ys) // 2]), np.full(4, spec.rx_height_m)], axis=1))

    t0 = time.perf_counter()
    full_cells, full_paths, blocked, _ = trace_grid(spec, rt, per_path=True, progress=False)
    full_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    diff_cells, diff_paths, _, _, record = differential.differential_trace(
        parent, parent_spec, spec, rt, radius_m=radius_m, per_path=True, tracer_factory=lambda: RayTracer(spec, rt)
    )
    diff_s = time.perf_counter() - t0
    mask, _ = differential.retrace_mask(parent_spec, spec, parent.table, radius_m=radius_m)
    retraced = mask.ravel()

    full = as_dataset("full", parent, full_cells, full_paths)
    diff = as_dataset("differential", parent, diff_cells, diff_paths)
    c = compare(full, diff)
    floor = compare(full, parent)
    row = {
        "scene": scene,
        "free_cells": record["free_cells"],
        "retraced_cells": record["retraced_cells"],
        "reasons": record["reasons"],
        "radius_m": record["radius_m"],
        "parent": record["parent"],
        "full_s": round(full_s, 2),
        "differential_s": round(diff_s, 2),
        "speedup": round(full_s / diff_s, 2),
        "differential_vs_full": {
            "all": stats(c, np.ones_like(retraced)),
            "retraced": stats(c, retraced),
            "kept": stats(c, ~retraced),
        },
        "parent_reused_vs_full": stats(floor, np.ones_like(retraced)),
    }
    if seed_floor:
        other = dataclasses.replace(rt, seed=rt.seed + 1)
        cells2, paths2, _, _ = trace_grid(spec, other, per_path=True, progress=False)
        row["full_other_seed_vs_full"] = stats(
            compare(full, as_dataset("seed", parent, cells2, paths2)), np.ones_like(retraced)
        )
    plot(spec, blocked, mask, c, out / f"bench_differential_{scene}.png", row)
    return row


def plot(spec, blocked, mask, c, path: Path, row: dict) -> None:
    import matplotlib  # here: the results pages import markdown() alone

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shape = blocked.shape
    img = np.zeros(shape)  # 0 free kept, 1 re-traced, 2 blocked, 3 disagrees with the full trace
    img[mask] = 1
    img[blocked] = 2
    img[(~c["agree"].reshape(shape)) & c["free"].reshape(shape)] = 3
    fig, ax = plt.subplots(figsize=(7, 7 * shape[0] / shape[1] + 0.8))
    cmap = matplotlib.colors.ListedColormap(["#f2f2f2", "#9ecae1", "#404040", "#d62728"])
    ax.imshow(img, origin="lower", cmap=cmap, vmin=0, vmax=3, interpolation="nearest")
    a = row["differential_vs_full"]
    ax.set_title(
        f"{row['scene']}/dynamic: {row['retraced_cells']} of {row['free_cells']} cells re-traced "
        f"(blue; dark: blocked), "
        f"{row['full_s']:.1f} s → {row['differential_s']:.1f} s\nred: strongest path differs from the full "
        f"re-trace ({100 * (1 - a['all']['agreement']):.1f} % of free cells)",
        fontsize=9,
    )
    ax.set(xlabel="ix", ylabel="iy")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=120)
    plt.close(fig)
    os.replace(tmp, path)


def markdown(rows: list[dict], described: str) -> str:
    """The report of one or more scenes' rows (the JSON of each, in order): a sentence and the table, as
    docs/results/ray-tracing.md shows it (``make results-pages`` renders it from the scenes' JSON alone)."""

    def pct(s):
        return f"{100 * s['agreement']:.1f} %"

    def count(n: int) -> str:
        return f"{n:,}".replace(",", " ")

    lines = [
        f"Differential vs full re-trace of each dynamic twin ({described}).",
        "",
        "| twin | re-traced | trace time full → differential | agreement with the full re-trace: all / "
        "re-traced / kept cells | median / p95 abs. gain diff | parent reused unchanged | a 2nd full trace "
        "(seed + 1) |",
        "|---|---:|---:|---|---:|---:|---:|",
    ]
    for r in rows:
        a = r["differential_vs_full"]
        seed = r.get("full_other_seed_vs_full")
        lines.append(
            f"| `{r['scene']}/dynamic` | {count(r['retraced_cells'])} of {count(r['free_cells'])} | "
            f"{r['full_s']:.1f} s → {r['differential_s']:.1f} s ({r['speedup']:.1f}×) | "
            f"{pct(a['all'])} / {pct(a['retraced'])} / {pct(a['kept'])} | "
            f"{a['all']['gain_median_db']:.3f} / {a['all']['gain_p95_db']:.2f} dB | "
            f"{pct(r['parent_reused_vs_full'])} | {pct(seed) if seed else 'not run'} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["cubicle"])
    ap.add_argument("--radius-m", type=float, default=BuildConfig.retrace_radius_m)
    ap.add_argument(
        "--no-seed-floor", dest="seed_floor", action="store_false", help="skip the second full trace with another seed"
    )
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()
    host = machine()  # before the runs: the load they start under
    rows = []
    for scene in args.scenes:
        row = bench_scene(scene, args.radius_m, args.seed_floor, args.out)
        rows.append(row)
        md = markdown([row], describe(host))
        write_atomic(args.out / f"bench_differential_{scene}.md", md)
        write_atomic(
            args.out / f"bench_differential_{scene}.json",
            json.dumps({**row, "machine": describe(host), "machine_details": host}, indent=2) + "\n",
        )
        print(md, flush=True)


if __name__ == "__main__":
    main()
