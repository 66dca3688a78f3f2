"""Channels from a stored dataset: how fast :mod:`dtradar_data.channels` generates them, and (``--check``) how close
they are to Sionna's own ``Paths.cfr()`` re-traced at the dataset's settings with the same arrays, on every free cell.

Timing: every free cell of the dataset, the paper's arrays (its transmitter array at its pose, its receiver), an OFDM
grid of ``--subcarriers`` at ``--spacing-hz``; the first call (which imports Sionna and compiles the pattern kernels)
and the best of ``--repeats`` warm calls, the per-path table already loaded (its load is timed apart). The check
re-traces the dataset's scene with its settings (batch-independent rows are the same whatever the call, so cells are
traced in calls of ``--check-batch``) once per array pair and reports each cell's NMSE ``‖H - H_sionna‖² / ‖H_sionna‖²``
over receive ports × transmit ports × subcarriers. Needs a version built with ``--rt.path-channels``.
Writes ``results/bench_channels_<scene>.{json,md}``.

    python -m dtradar_data build --scene cubicle --variant blueprint --rt.path-channels
    python bench/bench_channels.py --name cubicle/blueprint --check
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

import dtradar_data
from dtradar_data.channels import Array, ChannelGenerator, ofdm_frequencies
from dtradar_data.core.files import write_atomic
from dtradar_data.core.machine import describe, machine
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec

#: The array pairs of the check: the paper's, a 4 x 4 UPA to a 2-element receiver, and a turned cross-polarised pair.
PAIRS = {
    "paper": None,  # the dataset's own arrays
    "4x4 UPA tr38901 VH -> 1x2 dipole V": (Array(4, 4, "tr38901", "VH"), Array(1, 2, "dipole", "V"), None, (0, 0, 0)),
    "2x2 iso cross (turned) -> 1x2 hw_dipole VH (turned)": (
        Array(2, 2, "iso", "cross"),
        Array(1, 2, "hw_dipole", "VH"),
        (0.3, -0.2, 0.1),
        (0.4, 0.2, -0.3),
    ),
}


def paper_arrays(ds) -> tuple[Array, Array]:
    tx, rt = ds.meta["transmitter"], ds.meta["rt"]
    return Array(tx["num_rows"], tx["num_cols"], tx["pattern"], tx["polarization"]), Array(
        1, 1, rt["rx_pattern"], rt["rx_polarization"]
    )


def settings_of(ds) -> RTSettings:
    """The dataset's RT settings, rebuilt from its ``meta.json`` (checked: they hash as recorded)."""
    recorded = ds.meta["rt"]
    names = {f.name for f in dataclasses.fields(RTSettings)} - {"batch_independent", "path_channels"}
    s = RTSettings(
        **{k: v for k, v in recorded.items() if k in names},
        batch_independent="batch_independent" in recorded,
        path_channels="path_channels" in recorded,
        device="cpu",
    )
    assert all(recorded[k] == v for k, v in s.hashed().items()), "settings do not hash as the dataset records"
    return s


def sionna_cfr(tracer, points, settings, freqs, tx, rx, tx_ort, rx_ort, batch: int) -> np.ndarray:
    import drjit as dr

    scene = tracer.scene
    scene.tx_array, scene.rx_array = tx.sionna(), rx.sionna()
    scene.get("tx").orientation = list(tx_ort)
    out = []
    threads = dr.thread_count()
    dr.set_thread_count(1)  # as the dataset's trace (deterministic): the weak paths depend on it
    try:
        for s in range(0, len(points), batch):
            tracer._set_receivers(points[s : s + batch])
            for name in tracer._rx_names:
                scene.get(name).orientation = list(rx_ort)
            paths = tracer._solver(scene, **settings.solver_kwargs())
            if getattr(tracer._solver, "buffer_full", False):
                raise RuntimeError("the path buffer filled: use a smaller --check-batch")
            out.append(np.asarray(paths.cfr(frequencies=freqs, out_type="numpy"))[:, :, 0, :, 0, :])
    finally:
        dr.set_thread_count(threads)
    return np.concatenate(out)


def check(ds, freqs, batch: int) -> dict:
    from dtradar_data.pipeline.tracing import _receivers
    from dtradar_data.rt.tracer import RayTracer

    spec = load_scene_spec(ds.meta["scene"], ds.meta["variant"])
    assert spec.digest() == ds.meta["scene_hash"], "the scene file changed since the dataset was built"
    settings = settings_of(ds)
    rx = _receivers(spec)
    tracer = RayTracer(spec, settings)
    results = {}
    try:
        for label, pair in PAIRS.items():
            tx, rxa, tx_ort, rx_ort = (*paper_arrays(ds), None, (0.0, 0.0, 0.0)) if pair is None else pair
            gen = ChannelGenerator(ds, tx, rxa, frequencies_hz=freqs, tx_orientation=tx_ort, rx_orientation=rx_ort)
            h = gen.generate(np.stack([rx.ix, rx.iy], axis=1)).h
            ref = sionna_cfr(tracer, rx.points, settings, freqs, tx, rxa, gen.tx_orientation, rx_ort, batch)
            energy = np.sum(np.abs(ref) ** 2, axis=(1, 2, 3))
            has = energy > 0
            nmse = np.sum(np.abs(h - ref) ** 2, axis=(1, 2, 3))[has] / energy[has]
            db = 10 * np.log10(np.maximum(nmse, 1e-30))
            results[label] = {
                "cells": int(has.sum()),
                "cells_without_paths": int((~has).sum()),
                "nmse_db_max": float(db.max()),
                "nmse_db_median": float(np.median(db)),
                "ports": [rxa.num_ports, tx.num_ports],
            }
            print(f"  {label}: {has.sum()} cells, NMSE max {db.max():.1f} dB, median {np.median(db):.1f} dB")
    finally:
        tracer.close()
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--name", default="cubicle/blueprint")
    ap.add_argument("--subcarriers", type=int, default=64)
    ap.add_argument("--spacing-hz", type=float, default=30e3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--check", action="store_true", help="compare with Sionna's Paths.cfr on every free cell")
    ap.add_argument("--check-batch", type=int, default=128)
    ap.add_argument("--out", type=Path, default=Path("results"))
    args = ap.parse_args()

    t0 = time.perf_counter()
    ds = dtradar_data.load(args.name, paths=True)
    load_s = time.perf_counter() - t0
    freqs = ofdm_frequencies(args.subcarriers, args.spacing_hz)
    tx, rx = paper_arrays(ds)
    t0 = time.perf_counter()
    gen = ChannelGenerator(ds, tx, rx, frequencies_hz=freqs)
    out = gen.generate()
    first_s = time.perf_counter() - t0
    warm = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        out = ChannelGenerator(ds, tx, rx, frequencies_hz=freqs).generate()
        warm.append(time.perf_counter() - t0)
    host = machine()
    row = {
        "name": ds.name,
        "version": ds.version,
        "cells": len(out.ix),
        "paths": int(out.num_paths.sum()),
        "max_paths_per_cell": int(out.num_paths.max()),
        "h_shape": list(out.h.shape),
        "subcarriers": args.subcarriers,
        "spacing_hz": args.spacing_hz,
        "load_paths_s": round(load_s, 3),
        "first_call_s": round(first_s, 3),
        "warm_best_s": round(min(warm), 3),
        "warm_median_s": round(float(np.median(warm)), 3),
    }
    print(json.dumps(row))
    if args.check:
        row["check"] = check(ds, freqs, args.check_batch)
    md = [
        f"# Channels from {ds.name}@{ds.version}",
        "",
        f"Machine: {describe(host)}.",
        "",
        f"Paper arrays ({tx.num_rows}x{tx.num_cols} {tx.pattern} {tx.polarization} -> {rx.pattern} {rx.polarization}),"
        f" {args.subcarriers} subcarriers at {args.spacing_hz:g} Hz, {row['cells']} free cells, {row['paths']} paths:",
        "",
        "| load per-path table | first call | warm best | warm median |",
        "|---|---|---|---|",
        f"| {load_s:.2f} s | {first_s:.2f} s | {min(warm):.2f} s | {np.median(warm):.2f} s |",
    ]
    if args.check:
        md += ["", "Against Sionna's `Paths.cfr()` (same scene, settings, receivers, arrays), per cell:", ""]
        md += ["| arrays | ports (rx x tx) | cells | NMSE max (dB) | NMSE median (dB) |", "|---|---|---|---|---|"]
        for label, r in row["check"].items():
            md.append(
                f"| {label} | {r['ports'][0]} x {r['ports'][1]} | {r['cells']} | {r['nmse_db_max']:.1f} "
                f"| {r['nmse_db_median']:.1f} |"
            )
    args.out.mkdir(parents=True, exist_ok=True)
    scene = ds.name.split("/")[0]
    write_atomic(args.out / f"bench_channels_{scene}.md", "\n".join(md) + "\n")
    payload = {**row, "machine": describe(host), "machine_details": host}
    write_atomic(args.out / f"bench_channels_{scene}.json", json.dumps(payload, indent=2) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
