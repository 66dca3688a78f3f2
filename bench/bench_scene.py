"""The scene inside a dataset: plain Sionna opens the version's stored scene (``sionna.rt.load_scene(ds.scene_xml)``)
and re-traces its free cells at the version's settings with its own ``PathSolver``; how many cells get the stored
strongest path back (its delay within 30 ps, its reference-port power within 0.1 dB, line of sight or not), and how
long the re-trace takes. ``--against ROOT``: the same version stored in another data root (one built before versions
carried their scene) must have the same version hash and the same cells table: storing the scene moved nothing.
Writes ``results/bench_scene_<scene>.{json,md}``.

    DTRADAR_DATA_ROOT=/tmp/scene-root python -m dtradar_data build --scene cubicle --variant blueprint
    DTRADAR_DATA_ROOT=/tmp/scene-root python bench/bench_scene.py --name cubicle/blueprint --against ~/.cache/dtradar
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import dtradar_data
from dtradar_data.core.files import write_atomic
from dtradar_data.core.machine import describe, machine
from dtradar_data.rt.scene_retrace import retrace_strongest, stored_strongest, strongest_path_agreement


def same_as_before(ds, root: Path) -> dict:
    """The version ``ds`` is, loaded from data root ``root``: whether it is there and its cells table is ``ds``'s."""
    here = os.environ.get("DTRADAR_DATA_ROOT")
    os.environ["DTRADAR_DATA_ROOT"] = str(root)
    try:
        before = dtradar_data.load(ds.name, revision=ds.version)
    finally:
        if here is None:
            os.environ.pop("DTRADAR_DATA_ROOT")
        else:
            os.environ["DTRADAR_DATA_ROOT"] = here
    return {
        "root": str(root),
        "version": before.version,
        "tag": before.meta.get("tag"),
        "had_scene": "scene/scene.xml" in (before.meta.get("files") or {}),
        "cells_equal": before.table.equals(ds.table),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", default="cubicle/blueprint", help="dataset name[@revision], built with its scene")
    ap.add_argument("--batch", type=int, default=16, help="receivers per PathSolver call")
    ap.add_argument("--against", type=Path, default=None, help="a data root holding the same version, stored before")
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()

    ds = dtradar_data.load(args.name)
    t0 = time.perf_counter()
    retraced = retrace_strongest(ds, batch=args.batch)
    seconds = time.perf_counter() - t0
    row = {
        "name": ds.name,
        "version": ds.version,
        "scene_xml": str(ds.scene_xml),
        "scene_files": {k: v["bytes"] for k, v in sorted(ds.meta["files"].items()) if k.startswith("scene/")},
        "batch": args.batch,
        "retrace_seconds": round(seconds, 1),
        **strongest_path_agreement(stored_strongest(ds), retraced),
        **({"against": same_as_before(ds, args.against.expanduser())} if args.against else {}),
    }
    host = machine()
    scene = ds.name.split("/")[0]
    md = [
        f"# The scene inside {ds.name}",
        "",
        f"Version `{ds.version}`; plain `sionna.rt.load_scene` on its `scene/scene.xml`, Sionna's `PathSolver` at its "
        f"settings, {args.batch} receivers per call, one thread. Machine: {describe(host)}.",
        "",
        "| cells | same strongest path | fraction | same path count | max delay diff | max power diff | re-trace |",
        "|---|---|---|---|---|---|---|",
        f"| {row['cells']} | {row['same_strongest_path']} | {row['fraction']:.4f} | {row['same_num_paths']} | "
        f"{row['max_delay_diff_s']:.2e} s | {row['max_power_diff_db']:.3f} dB | {row['retrace_seconds']} s |",
    ]
    if args.against:
        a = row["against"]
        md += [
            "",
            f"Against {a['root']}: version {a['version']} ({a['tag']}), stored there "
            f"{'with' if a['had_scene'] else 'without'} its scene; cells table equal: {a['cells_equal']}.",
        ]
    args.out.mkdir(parents=True, exist_ok=True)
    write_atomic(args.out / f"bench_scene_{scene}.md", "\n".join(md) + "\n")
    payload = {**row, "machine": describe(host), "machine_details": host}
    write_atomic(args.out / f"bench_scene_{scene}.json", json.dumps(payload, indent=2) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
