"""A moving twin built snapshot by snapshot against a full trace of every snapshot, side by side in one run.

For each scene: load its moving twin (:func:`dtradar_data.scenes.load_moving_scene`), compile the kernels first on a
few cells (the first JIT compile, reported apart), then build the twin's ``T`` snapshots with the library's own code
path, the one ``make dataset VARIANT=moving`` runs (:func:`dtradar_data.pipeline.moving.trace_snapshots` with the
build's :func:`~dtradar_data.pipeline.tracing.trace_grid` for snapshot 0, then
:func:`~dtradar_data.pipeline.moving.moving_tables`; into a temporary work folder), and trace every snapshot ``k >= 1``
in full as well (``MovingScene.spec_at(k)``, a static scene, by ``trace_grid``); snapshot 0 of the build is itself a
full trace and serves as its own reference. Reported per snapshot and in total: cells re-traced, differential and
full seconds and their ratio, and how each differential snapshot agrees with the full trace of the same instant
(the strongest-path rule of :mod:`dtradar_data.rt.compare`, in all free cells, the re-traced and the kept ones;
absolute total-gain differences); beside it the seed-noise floor (a second full trace of a snapshot with seed + 1)
and, as the price of not tracing the movers at all, snapshot 0 reused unchanged. Then whether the goals are met:
every differential snapshot >= 3x cheaper than a full trace (on Dallas Q3) at the noise floor's agreement, and a
60-snapshot cubicle twin built in <= 3 min.

``--snapshots`` longer than the scene's own horizon (the movers' common period, 16 snapshots in the cubicle) runs the
movers on round their routes (``dataclasses.replace(moving, snapshots=T)``: positions are periodic, so snapshot
``k`` shows the movers where snapshot ``k mod period`` does), and every snapshot is still traced from the one before,
so 60 cubicle snapshots are 59 differential steps. Writes ``results/bench_moving_<scene>.{json,md,png}``.

    python bench/bench_moving.py                                   # cubicle 60 snapshots, dallas-q3 4
    python bench/bench_moving.py --scenes cubicle --snapshots 20 --seed-floor 0 10 19
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_moving_report import markdown, plot  # beside this script in bench/ (on its path)

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import write_atomic
from dtradar_data.core.machine import describe, machine
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import differential, moving
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.trace_helpers import helper_count
from dtradar_data.pipeline.tracing import trace_grid
from dtradar_data.rt.compare import compare
from dtradar_data.rt.compare import summarize as stats
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import RayTracer
from dtradar_data.scenes import load_moving_scene

#: Snapshots per scene by default: the issue's 60 in the cubicle (about 3 s per full trace here); Dallas Q3's full
#: trace takes about 3 min on 2 cores, so a few snapshots only (each is one more full trace).
DEFAULT_SNAPSHOTS = {"cubicle": 60, "dallas-q3": 4}
FALLBACK_SNAPSHOTS = 8
SPEEDUP_GOAL = 3.0  # each differential snapshot at least this many times cheaper than a full trace (Dallas Q3)
BUILD_GOAL_S = 180.0  # a 60-snapshot cubicle twin in at most 3 min on 2 cores
BUILD_GOAL_SNAPSHOTS = 60
#: A full trace shorter than this is cheap enough to take the seed floor at three snapshots by default, not one.
CHEAP_FULL_S = 30.0


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def snapshot_counts(items: list[str] | None, scenes: list[str]) -> dict[str, int]:
    """``--snapshots`` as ``{scene: T}``: each item ``N`` (every scene) or ``SCENE=N``; defaults per scene."""
    out = {s: DEFAULT_SNAPSHOTS.get(s, FALLBACK_SNAPSHOTS) for s in scenes}
    for item in items or []:
        scene, sep, n = item.rpartition("=")
        try:
            count = int(n)
        except ValueError:
            raise SystemExit(f"--snapshots {item!r}: give N or SCENE=N, e.g. --snapshots cubicle=60") from None
        if count < 2:
            raise SystemExit(f"--snapshots {item!r}: at least 2 (snapshot 0 is a full trace, 1 the first differential)")
        if sep and scene not in out:
            raise SystemExit(f"--snapshots {item!r}: {scene!r} is not one of --scenes {' '.join(scenes)}")
        for s in [scene] if sep else scenes:
            out[s] = count
    return out


def with_horizon(moving_scene, snapshots: int):
    """The moving twin over ``snapshots`` snapshots (longer or shorter than its own horizon: the movers are
    periodic), recorded in its provenance; the scene unchanged when it already has that many."""
    if snapshots == moving_scene.snapshots:
        return moving_scene
    provenance = {**moving_scene.provenance, "snapshots": snapshots, "horizon_from": "bench_moving --snapshots"}
    return dataclasses.replace(moving_scene, snapshots=snapshots, provenance=provenance)


def as_dataset(name: str, grid: dict, cells, paths) -> Dataset:
    return Dataset(name=name, table=cells, meta={"grid": grid}, paths_table=paths)


def seed_floor_snapshots(requested: list[int] | None, count: int, full0_s: float) -> list[int]:
    """Where to take the seed-noise floor: as asked (in range), else snapshot 0, the middle one and the last when a
    full trace is cheap (< :data:`CHEAP_FULL_S`), snapshot 0 only otherwise."""
    if requested is not None:
        return sorted({k for k in requested if 0 <= k < count})
    if full0_s < CHEAP_FULL_S:
        return sorted({0, count // 2, count - 1})
    return [0]


def bench_scene(
    scene: str, count: int, radius_m: float, floor_at: list[int] | None, tol_pp: float, stock_solver: bool
) -> dict:
    """One scene's moving twin: built snapshot by snapshot, every snapshot traced in full beside it, the seed-noise
    floor, and the summary (see the module docstring)."""
    host_before = machine()
    mv, period, config = _moving_twin(scene, count, radius_m, stock_solver)
    rt = config.rt
    spec0 = mv.spec_at(0)
    grid = spec0.grid.to_dict()
    log(f"{scene}: {count} snapshots of {mv.dt_s:g} s (own horizon {period}), {grid['nx']} x {grid['ny']} cells")
    compile_s = _first_compile(spec0, rt)
    log(f"{scene}: first compile {compile_s:.1f} s")
    helpers = helper_count(int((~occupancy(spec0)).sum()), rt)  # what the build starts beside it, as it decides
    snaps, trace_s, tables_s = _build(mv, config)
    log(f"{scene}: built {count} snapshots in {trace_s:.1f} s (+ {tables_s:.1f} s joining the table)")
    rows, kept_full, floor_ks = _compare_with_full(scene, count, mv, period, config, grid, snaps, floor_at)
    floors = _seed_floor(scene, mv, config, grid, kept_full, floor_ks)
    host_after = machine()
    return summarize(
        scene,
        mv,
        period,
        rt,
        config,
        rows,
        floors,
        compile_s=compile_s,
        trace_s=trace_s,
        tables_s=tables_s,
        tol_pp=tol_pp,
        helpers=helpers,
        host_before=host_before,
        host_after=host_after,
    )


def _moving_twin(scene: str, count: int, radius_m: float, stock_solver: bool):
    """The scene's moving twin over ``count`` snapshots, its own horizon and the build's config for it (the
    settings ``make dataset VARIANT=moving`` would use, with ``--radius-m`` as its re-trace radius)."""
    base_moving = load_moving_scene(scene)
    period = base_moving.snapshots
    mv = with_horizon(base_moving, count)
    base = BuildConfig(
        scene=scene,
        variant="moving",
        progress=False,
        retrace_radius_m=radius_m,
        rt=RTSettings(batch_independent=not stock_solver),
    )
    return mv, period, scene_config(base, mv.base)


def _first_compile(spec0, rt: RTSettings) -> float:
    """Seconds of the first JIT compile, paid on a few cells of snapshot 0 so that no timed trace pays for it."""
    t0 = time.perf_counter()
    warm = RayTracer(spec0, rt)
    xs, ys = spec0.grid.centres()
    free_iy, free_ix = np.nonzero(~occupancy(spec0))
    pick = np.linspace(0, len(free_ix) - 1, 4).round().astype(int)
    warm.trace(np.stack([xs[free_ix[pick]], ys[free_iy[pick]], np.full(4, spec0.rx_height_m)], axis=1))
    warm.close()
    return time.perf_counter() - t0


def _build(mv, config):
    """The moving twin as `make dataset VARIANT=moving` builds it (dtradar_data.pipeline.moving_build's calls), in a
    temporary work folder: its snapshots, the seconds tracing them and the seconds joining the table."""
    rt = config.rt
    with tempfile.TemporaryDirectory(prefix="dtradar-bench-moving-") as tmp:

        def full_trace(spec, batch_dir: Path):
            return trace_grid(spec, rt, batch_dir, per_path=config.per_path, progress=False)

        t0 = time.perf_counter()
        snaps = moving.trace_snapshots(
            mv,
            rt,
            Path(tmp) / "work",
            radius_m=config.retrace_radius_m,
            per_path=config.per_path,
            full_trace=full_trace,
            progress=True,
        )
        trace_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        moving.moving_tables(mv, snaps)
        tables_s = time.perf_counter() - t0
    return snaps, trace_s, tables_s


def _snapshot0_row(snap0) -> dict:
    """Snapshot 0's row: the build traced it in full, so it has no full trace of its own to compare with."""
    return {
        "k": 0,
        "t_s": 0.0,
        "mode": "full",
        "retraced_cells": snap0.record["retraced_cells"],
        "free_cells": snap0.record["free_cells"],
        "differential_s": snap0.record["seconds"],
        "full_s": snap0.record["seconds"],
        "note": "the build's snapshot 0 is a full trace: it is its own reference",
    }


def _compare_with_full(scene: str, count: int, mv, period: int, config, grid: dict, snaps, floor_at: list[int] | None):
    """Every snapshot ``k >= 1`` traced in full and compared with the differential one: the rows, the full traces
    kept for later comparisons (one period's, and those at the seed floor's snapshots) and those snapshots."""
    full0 = as_dataset("full", grid, snaps[0].cells, snaps[0].paths)
    rows = [_snapshot0_row(snaps[0])]
    floor_ks = seed_floor_snapshots(floor_at, count, snaps[0].record["seconds"])
    previous_full = full0
    kept_full: dict[int, Dataset] = {0: full0}  # one period of full traces: a repeated instant is compared with it
    for k in range(1, count):
        spec = mv.spec_at(k)
        t0 = time.perf_counter()
        cells, paths, _, _ = trace_grid(spec, config.rt, per_path=config.per_path, progress=False)
        full_s = time.perf_counter() - t0
        full = as_dataset("full", grid, cells, paths)
        row = _differential_row(k, mv, spec, config, grid, snaps, full, full_s, previous_full, full0)
        if k >= period and mv.spec_at(k % period).objects == spec.objects:
            # the movers are back where they were a whole number of periods ago: the same scene, the same seed
            row["full_vs_full_periods_before"] = stats(compare(full, kept_full[k % period]))
        if k < period or k in floor_ks:
            kept_full[k] = full
        previous_full = full
        rows.append(row)
        a = row["differential_vs_full"]
        log(
            f"{scene} t={k}: {row['retraced_cells']}/{row['free_cells']} re-traced, {row['differential_s']:.2f} s vs "
            f"{full_s:.2f} s full; agreement {100 * a['all']['agreement']:.1f} % (re-traced "
            f"{100 * a['retraced']['agreement']:.1f} %, kept {100 * a['kept']['agreement']:.1f} %)"
        )
    return rows, kept_full, floor_ks


def _retraced(k: int, mv, spec, config, snaps) -> np.ndarray:
    """The cells snapshot ``k`` re-traced (flat), recomputed here so that the comparison can be split into re-traced
    and kept cells; it must match the build's count, or the split would describe another re-trace than the build's."""
    changes = mv.changed_between(k - 1, k)
    mask, _ = differential.retrace_mask(
        mv.spec_at(k - 1),
        spec,
        snaps[k - 1].cells,
        radius_m=config.retrace_radius_m,
        changed=[c.before for c in changes] + [c.after for c in changes],
    )
    if int(mask.sum()) != snaps[k].record["retraced_cells"]:
        raise AssertionError(f"snapshot {k}: the re-trace mask differs from the build's")
    return mask.ravel()


def _differential_row(k: int, mv, spec, config, grid: dict, snaps, full, full_s: float, previous_full, full0) -> dict:
    """Differential snapshot ``k`` against its full trace: cells, seconds, speed-up and agreement (in all, the
    re-traced and the kept cells), beside the previous snapshot's and snapshot 0's full traces (the price of not
    re-tracing the movers at all)."""
    snap = snaps[k]
    retraced = _retraced(k, mv, spec, config, snaps)
    c = compare(full, as_dataset("differential", grid, snap.cells, snap.paths))
    diff_s = snap.record["seconds"]
    return {
        "k": k,
        "t_s": round(k * mv.dt_s, 6),
        "mode": "differential",
        "retraced_cells": snap.record["retraced_cells"],
        "free_cells": snap.record["free_cells"],
        "reasons": snap.record["reasons"],
        "movers_moved": len(snap.record["movers_moved"]),
        "differential_s": diff_s,
        "full_s": round(full_s, 3),
        "speedup": round(full_s / diff_s, 3) if diff_s > 0 else None,
        "differential_vs_full": {
            "all": stats(c),
            "retraced": stats(c, retraced),
            "kept": stats(c, ~retraced),
        },
        "previous_full_vs_full": stats(compare(full, previous_full)),
        "snapshot0_vs_full": stats(compare(full, full0)),
    }


def _seed_floor(scene: str, mv, config, grid: dict, kept_full: dict, floor_ks: list[int]) -> list[dict]:
    """The seed-noise floor: a second full trace of each of ``floor_ks`` with seed + 1, against the kept one."""
    floors = []
    rt = config.rt
    other = dataclasses.replace(rt, seed=rt.seed + 1)
    for k in floor_ks:
        cells2, paths2, _, _ = trace_grid(mv.spec_at(k), other, per_path=config.per_path, progress=False)
        floors.append(
            {"k": k, "seed": other.seed, **stats(compare(kept_full[k], as_dataset("seed", grid, cells2, paths2)))}
        )
        log(f"{scene}: seed floor at t={k}: {100 * floors[-1]['agreement']:.1f} %")
    return floors


def summarize(
    scene, mv, period, rt, config, rows, floors, *, compile_s, trace_s, tables_s, tol_pp, helpers=0, **hosts
) -> dict:
    diff = [r for r in rows if r["mode"] == "differential"]
    agree = np.array([r["differential_vs_full"]["all"]["agreement"] for r in diff])
    speed = np.array([r["speedup"] for r in diff], dtype=float)
    diff_total = float(sum(r["differential_s"] for r in diff))
    full_total = float(sum(r["full_s"] for r in diff))
    floor_min = min(f["agreement"] for f in floors) if floors else float("nan")
    at_floor = [bool(a >= floor_min - tol_pp / 100) for a in agree] if floors else []
    build_s = trace_s + tables_s
    goals = {
        "speedup": {
            "goal": f"every differential snapshot >= {SPEEDUP_GOAL:g}x cheaper than a full trace (set on dallas-q3)",
            "min": float(speed.min()),
            "snapshots_meeting": int((speed >= SPEEDUP_GOAL).sum()),
            "of": len(diff),
            "met": bool((speed >= SPEEDUP_GOAL).all()),
        },
        "agreement": {
            "goal": f"every differential snapshot's agreement >= the seed floor's lowest - {tol_pp:g} pp",
            "floor_min": floor_min,
            "min": float(agree.min()),
            "mean": float(agree.mean()),
            "snapshots_meeting": int(sum(at_floor)),
            "of": len(diff),
            "met": bool(all(at_floor)) if floors else None,
        },
    }
    goals["build_time"] = {
        "goal": f"a {BUILD_GOAL_SNAPSHOTS}-snapshot cubicle twin in <= {BUILD_GOAL_S:g} s on 2 cores (set on cubicle)",
        "snapshots": len(rows),
        "warm_s": round(build_s, 2),
        "with_first_compile_s": round(build_s + compile_s, 2),
        "met": bool(build_s <= BUILD_GOAL_S) if len(rows) == BUILD_GOAL_SNAPSHOTS else None,
    }
    return {
        "scene": scene,
        "snapshots": len(rows),
        "own_horizon": period,
        "dt_s": mv.dt_s,
        "movers": len(mv.movers),
        "grid": [mv.base.grid.nx, mv.base.grid.ny],
        "rt": {k: getattr(rt, k) for k in ("max_depth", "samples_per_src", "batch_size", "seed", "batch_independent")},
        "radius_m": max(config.retrace_radius_m, mv.base.grid.cell_m),
        "helpers": helpers,  # processes tracing parts of each differential snapshot beside the build's (0: one)
        "first_compile_s": round(compile_s, 2),
        "build_trace_s": round(trace_s, 2),
        "build_tables_s": round(tables_s, 2),
        "differential_total_s": round(diff_total, 2),
        "full_total_s": round(full_total, 2),
        "speedup_total": round(full_total / diff_total, 3) if diff_total > 0 else None,
        "speedup_median": float(np.median(speed)),
        "retraced_fraction_mean": float(np.mean([r["retraced_cells"] / r["free_cells"] for r in diff])),
        "agreement_mean": float(agree.mean()),
        "agreement_min": float(agree.min()),
        "seed_floor": floors,
        "goals": goals,
        "per_snapshot": rows,
        "machine": describe(hosts["host_before"]),
        "machine_after": describe(hosts["host_after"]),
        "machine_details": hosts["host_before"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=["cubicle", "dallas-q3"])
    ap.add_argument(
        "--snapshots",
        nargs="+",
        metavar="[SCENE=]T",
        help="snapshots per scene: T for every scene or SCENE=T (default: cubicle=60, dallas-q3=4: a full Dallas Q3 "
        f"trace takes minutes; other scenes {FALLBACK_SNAPSHOTS})",
    )
    ap.add_argument(
        "--radius-m",
        type=float,
        default=BuildConfig.retrace_radius_m,
        help="re-trace radius around what moved between snapshots, metres (the build's --retrace-radius-m)",
    )
    ap.add_argument(
        "--seed-floor",
        nargs="*",
        type=int,
        metavar="K",
        help="snapshots at which to trace a second full trace with seed + 1 (the noise floor); with no K none. "
        f"Default: 0, the middle and the last one when a full trace takes < {CHEAP_FULL_S:g} s, else 0",
    )
    ap.add_argument(
        "--floor-tolerance-pp",
        type=float,
        default=0.5,
        help="a snapshot agrees 'at the noise floor' when within this many percentage points of the lowest floor",
    )
    ap.add_argument(
        "--stock-solver",
        action="store_true",
        help="trace with Sionna's own PathSolver (--rt.no-batch-independent, the engine before batch-independent "
        "tracing became the default); results go to bench_moving_<scene>-stock.*",
    )
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()
    counts = snapshot_counts(args.snapshots, args.scenes)
    for scene in args.scenes:
        res = bench_scene(
            scene, counts[scene], args.radius_m, args.seed_floor, args.floor_tolerance_pp, args.stock_solver
        )
        md = markdown(res)
        stem = f"bench_moving_{scene}" + ("-stock" if args.stock_solver else "")
        plot(res, args.out / f"{stem}.png")
        write_atomic(args.out / f"{stem}.md", md)
        write_atomic(args.out / f"{stem}.json", json.dumps(res, indent=2) + "\n")
        print(md, flush=True)


if __name__ == "__main__":
    main()
