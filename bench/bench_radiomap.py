"""Per-cell PathSolver gain against Sionna's own RadioMapSolver on one twin, each ablation side by side in one run.

Both sides trace the same scene (transmitter, materials, interactions, depth) and are compared in dB, PathSolver
minus radio map, over the grid's free cells (median, median of the absolute difference, its 90th percentile). The
PathSolver receivers are isotropic and dual-polarised (``iso``, ``VH``), so one trace gives every reduction of the
channel coefficients ``a[rx port, tx port, path]``, each summed incoherently over the paths:

* ``table``: ``|a|²`` averaged over the 32 TX ports, the V port of the receiver only: the dataset table's reduction
  (:mod:`dtradar_data.rt.features`) with an isotropic vertical receiver.
* ``full-pol ports``: the same, both receiver ports summed (all the field's power: no receiver pattern).
* ``precoded``: ``Σ_rx |Σ_tx a·p|²`` with RadioMapSolver's default precoding ``p = 1/√32``: what the radio map sums
  for each ray tube (``PlanarRadioMap.add_paths``: the precoded field's squared norm, both polarisations).

The ablations, one change at a time: the reduction (antennas), the dataset's dipole receiver, a port-averaged radio
map (one run per TX polarisation with a one-hot precoding: with a synthetic array ``|a|²`` is the same for every
element of one polarisation); the area (PathSolver averaged over k×k points inside each cell against a radio map
k times finer); the interactions (LoS only, LoS + specular at each depth, the dataset's setting, + diffraction);
the samples (radio map 1e6..; PathSolver 1e4 and more; Sionna's own PathSolver beside the batch-independent one).
Writes ``results/bench_radiomap/bench_radiomap.{json,md,png}`` (:mod:`bench_radiomap_report`: the report, whose summary
is the two tables of docs/results/ray-tracing.md).

    python bench/bench_radiomap.py                                    # cubicle, about 5 min on 2 cores
    python bench/bench_radiomap.py --rm-samples 1000000 --ps-samples 10000 --subpoints 2 --no-diffraction
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_radiomap_report import markdown, plot  # beside this script in bench/ (on its path)

from dtradar_data.core.machine import describe, machine
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.rt.settings import RTSettings
from dtradar_data.rt.tracer import RayTracer
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store.versions import library_versions

REDUCTIONS = ("table", "full-pol ports", "precoded")


def _parse_args() -> argparse.Namespace:
    """The command line (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="cubicle")
    ap.add_argument("--variant", default="blueprint")
    ap.add_argument("--ps-samples", type=int, default=RTSettings().samples_per_src, help="PathSolver samples_per_src")
    ap.add_argument("--rm-samples", type=int, default=10_000_000, help="RadioMapSolver samples_per_tx")
    ap.add_argument("--rm-sweep", type=int, nargs="*", default=[1_000_000], help="further radio-map sample counts")
    ap.add_argument("--ps-sweep", type=int, nargs="*", default=[100_000], help="further PathSolver sample counts")
    ap.add_argument("--subpoints", type=int, default=2, help="area ablation: k x k PathSolver points per cell")
    ap.add_argument("--depths", type=int, nargs="*", default=[1, 2, 3, 5], help="LoS + specular ablation depths")
    ap.add_argument("--solo-every", type=int, default=8, help="Sionna's solver one receiver per call: every n-th cell")
    ap.add_argument("--no-diffraction", action="store_true", help="skip the + diffraction row")
    ap.add_argument("--batch", type=int, default=600, help="receivers per PathSolver call (halved when it fills)")
    ap.add_argument("--out", type=Path, default=Path("results/bench_radiomap"))
    return ap.parse_args()


def _grid(spec, k: int = 1):
    """The radio map's plane (centre at receiver height, size, cell) aligned with the grid, the free cells' indices,
    and the PathSolver points: k x k per free cell, centred in its k x k sub-cells (k = 1: the cell centre)."""
    g = spec.grid
    blocked = occupancy(spec)
    iy, ix = np.nonzero(~blocked)
    xs, ys = g.centres()
    off = ((np.arange(k) + 0.5) / k - 0.5) * g.cell_m
    ox, oy = np.meshgrid(off, off, indexing="xy")
    px = (xs[ix][:, None] + ox.ravel()[None, :]).ravel()
    py = (ys[iy][:, None] + oy.ravel()[None, :]).ravel()
    points = np.stack([px, py, np.full(px.shape, spec.rx_height_m)], axis=1)
    width, height = g.nx * g.cell_m, g.ny * g.cell_m
    centre = (g.x0_m - g.cell_m / 2 + width / 2, g.y0_m - g.cell_m / 2 + height / 2, spec.rx_height_m)
    return {"centre": centre, "size": (width, height), "cell_m": g.cell_m, "ix": ix, "iy": iy, "points": points}


class Bench:
    """One scene's tracer (isotropic dual-polarised receivers) and both solvers, called with explicit settings."""

    def __init__(self, spec):
        self.base = RTSettings(device="cpu", rx_pattern="iso", rx_polarization="VH")
        self.tracer = RayTracer(spec, self.base)  # configures LLVM and the variant; the scene and TX as datasets
        from dtradar_data.rt.batch_independent_solver import BatchIndependentPathSolver  # after the tracer: see it

        self.solvers = {"batch-independent": BatchIndependentPathSolver(), "sionna": self.tracer.rt.PathSolver()}
        self._rx: list[str] = []

    def _receivers(self, points: np.ndarray, pattern: str, polarization: str) -> None:
        rt, scene = self.tracer.rt, self.tracer.scene
        scene.rx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern=pattern, polarization=polarization)
        for name in self._rx:
            scene.remove(name)
        self._rx = [f"bench-rx{i}" for i in range(len(points))]
        for name, p in zip(self._rx, points):
            scene.add(rt.Receiver(name, position=[float(v) for v in p]))

    def paths(self, points, settings: RTSettings, solver="batch-independent", rx=("iso", "VH")) -> np.ndarray:
        """``a[N, rx port, tx port, P]`` (invalid paths zeroed). The batch-independent solver's calls are halved
        while the path buffer fills, as RayTracer.trace does, so no receiver loses paths to the others."""
        import drjit as dr

        if solver == "sionna" or len(points) <= settings.batch_size:
            self._receivers(points, *rx)
            threads = dr.thread_count()
            dr.set_thread_count(1)  # as the tracer pins it: multi-threaded collection varies the weak paths
            try:
                p = self.solvers[solver](self.tracer.scene, **settings.solver_kwargs())
            finally:
                dr.set_thread_count(threads)
            full = solver != "sionna" and self.solvers[solver].buffer_full
            if not full or len(points) == 1:
                a = (np.asarray(p.a[0]) + 1j * np.asarray(p.a[1]))[:, :, 0, :, :]
                return (a * np.asarray(p.valid)[:, 0, None, None, :]).astype(np.complex64)
            settings = replace(settings, batch_size=max(1, len(points) // 2))
        step = settings.batch_size
        return np.concatenate(
            _padded([self.paths(points[i : i + step], settings, solver, rx) for i in range(0, len(points), step)])
        )

    def radio_map(self, grid, settings: RTSettings, samples: int, *, fine: int = 1, port: int | None = None):
        """RadioMapSolver path gain ``[ny·fine, nx·fine]`` on the grid's plane at receiver height; ``port``: a one-hot
        precoding on that TX port (else Sionna's default, all ports 1/√N)."""
        mi = self.tracer.mi
        precoding = None
        if port is not None:
            n = self.tracer.scene.tx_array.num_ant
            re = np.zeros(n, np.float32)
            re[port] = 1.0
            precoding = (mi.TensorXf(re), mi.TensorXf(np.zeros(n, np.float32)))
        return self.tracer.radio_map(
            centre_m=grid["centre"],
            size_m=grid["size"],
            cell_m=grid["cell_m"] / fine,
            samples_per_tx=samples,
            settings=settings,
            precoding_vec=precoding,
        )


def reduce(a: np.ndarray) -> dict[str, np.ndarray]:
    """Per receiver, linear and summed over paths: each reduction of the module docstring (RX port 0 is V)."""
    p2 = np.abs(a.astype(np.complex128)) ** 2
    n_tx = a.shape[2]
    return {
        "table": p2[:, 0].mean(axis=1).sum(axis=-1),
        "full-pol ports": p2.mean(axis=2).sum(axis=(1, -1)),
        "precoded": (np.abs(a.astype(np.complex128).sum(axis=2)) ** 2 / n_tx).sum(axis=(1, -1)),
    }


def num_paths(a: np.ndarray) -> int:
    """Valid paths over all receivers (zeroed ones are invalid or padding)."""
    return int((np.abs(a).sum(axis=(1, 2)) > 0).sum())


def stats(ps: np.ndarray, rm: np.ndarray) -> dict:
    """PathSolver minus radio map in dB over the cells where both are positive."""
    with np.errstate(divide="ignore", invalid="ignore"):
        d = 10 * np.log10(ps) - 10 * np.log10(rm)
    ok = np.isfinite(d)
    d = d[ok]
    return {
        "cells": int(d.size),
        "median_db": round(float(np.median(d)), 2),
        "median_abs_db": round(float(np.median(np.abs(d))), 2),
        "p90_abs_db": round(float(np.percentile(np.abs(d), 90)), 2),
        "mean_linear_ratio_db": round(float(10 * np.log10(np.mean(ps[ok]) / np.mean(rm[ok]))), 2),
    }


def _timed(f, *args, **kwargs):
    t0 = time.perf_counter()
    out = f(*args, **kwargs)
    return out, round(time.perf_counter() - t0, 1)


def _row(group, what, ps, rm, ps_s, rm_s, **extra) -> dict:
    row = {"group": group, "what": what, **stats(ps, rm), "ps_s": ps_s, "rm_s": rm_s, **extra}
    print(row, flush=True)
    return row


def antennas(b: Bench, grid, args, s: RTSettings, rows: list) -> dict:
    """The default settings: every reduction, the dipole receiver and a port-averaged radio map (hypothesis 3)."""
    a, ps_s = _timed(b.paths, grid["points"], s)
    rm, rm_s = _timed(b.radio_map, grid, s, args.rm_samples)
    rm_cells = rm[grid["iy"], grid["ix"]]
    red = reduce(a)
    for name in REDUCTIONS:
        rows.append(
            _row(
                "antennas",
                f"{name} vs radio map (default precoding)",
                red[name],
                rm_cells,
                ps_s,
                rm_s,
                paths=num_paths(a),
            )
        )
    # the two steps between the table and the radio map, both sides PathSolver: the receiver's H port, then the beam
    rows.append(
        _row(
            "antennas", "  step 1: table vs full-pol ports (PathSolver both)", red["table"], red["full-pol ports"], 0, 0
        )
    )
    rows.append(
        _row(
            "antennas",
            "  step 2: full-pol ports vs precoded (PathSolver both)",
            red["full-pol ports"],
            red["precoded"],
            0,
            0,
        )
    )
    dip, dip_s = _timed(b.paths, grid["points"], s, rx=("dipole", "V"))
    rows.append(
        _row("antennas", "dataset's dipole V, port mean vs radio map", reduce(dip)["table"], rm_cells, dip_s, 0)
    )
    n = b.tracer.scene.tx_array.num_ant  # ports: [polarisation, element]; element 0 of each polarisation
    ports, port_s = _timed(lambda: [b.radio_map(grid, s, args.rm_samples, port=p) for p in (0, n // 2)])
    rm_ports = np.mean(ports, axis=0)[grid["iy"], grid["ix"]]
    rows.append(
        _row("antennas", "full-pol ports vs port-averaged radio map", red["full-pol ports"], rm_ports, 0, port_s)
    )
    return {"rm": rm_cells, "red": red, "dipole": reduce(dip)["table"]}


def area(b: Bench, spec, args, s: RTSettings, rows: list, ref: dict) -> None:
    """Hypothesis 1: cell centre against cell mean, matched resolutions (the precoded reduction); with the datasets'
    interactions and with LoS only (where a cell half in a cubicle's shadow is all or nothing at its centre)."""
    k, cell = args.subpoints, spec.grid.cell_m
    g1, gk = _grid(spec), _grid(spec, k)
    a, ps_s = _timed(b.paths, gk["points"], s)
    sub = reduce(a)["precoded"].reshape(-1, k * k)  # [free cell, k*k points] in the sub-cells' row-major order
    fine, rm_s = _timed(b.radio_map, g1, s, args.rm_samples, fine=k)
    ny, nx = fine.shape[0] // k, fine.shape[1] // k
    blocks = fine.reshape(ny, k, nx, k).transpose(0, 2, 1, 3).reshape(ny, nx, k * k)[g1["iy"], g1["ix"]]
    centre, coarse = ref["red"]["precoded"], ref["rm"]
    rows.append(_row("area", f"centre point vs {cell:g} m cell (as above)", centre, coarse, 0, 0))
    rows.append(_row("area", f"mean of {k}x{k} points vs {cell:g} m cell", sub.mean(axis=1), coarse, ps_s, 0))
    rows.append(
        _row("area", f"mean of {k}x{k} points vs mean of {k}x{k} sub-cells", sub.mean(1), blocks.mean(1), 0, rm_s)
    )
    rows.append(_row("area", f"each point vs its {cell / k:g} m sub-cell", sub.ravel(), blocks.ravel(), 0, 0))
    los = replace(s, max_depth=0, specular_reflection=False, refraction=False)
    rm = b.radio_map(g1, los, args.rm_samples)[g1["iy"], g1["ix"]]
    rows.append(
        _row(
            "area",
            f"LoS only: centre point vs {cell:g} m cell",
            reduce(b.paths(g1["points"], los))["precoded"],
            rm,
            0,
            0,
        )
    )
    sub = reduce(b.paths(gk["points"], los))["precoded"].reshape(-1, k * k).mean(axis=1)
    rows.append(_row("area", f"LoS only: mean of {k}x{k} points vs {cell:g} m cell", sub, rm, 0, 0))


def _ps_row(group: str, what: str, a: np.ndarray, rm: np.ndarray, ps_s: float, rm_s: float) -> dict:
    """A PathSolver trace (the precoded reduction) against a radio map, with the table reduction's median beside."""
    red = reduce(a)
    table = stats(red["table"], rm)["median_db"]
    return _row(group, what, red["precoded"], rm, ps_s, rm_s, table_median_db=table, paths=num_paths(a))


def interactions(b: Bench, grid, args, s: RTSettings, rows: list) -> None:
    """Hypothesis 2: the same interaction settings on both sides, one type or depth at a time."""
    configs = [("LoS only", replace(s, max_depth=0, specular_reflection=False, refraction=False))]
    configs += [(f"LoS + specular, depth {d}", replace(s, max_depth=d, refraction=False)) for d in args.depths]
    configs += [(f"LoS + refraction, depth {s.max_depth}", replace(s, specular_reflection=False))]
    configs += [(f"LoS + specular + refraction, depth {s.max_depth} (datasets)", s)]
    if not args.no_diffraction:
        configs += [(f"+ diffraction, depth {s.max_depth}", replace(s, diffraction=True))]
    for what, c in configs:
        a, ps_s = _timed(b.paths, grid["points"], c)
        rm, rm_s = _timed(b.radio_map, grid, c, args.rm_samples)
        rows.append(_ps_row("interactions", what, a, rm[grid["iy"], grid["ix"]], ps_s, rm_s))


def samples(b: Bench, grid, args, s: RTSettings, rows: list, ref: dict) -> None:
    """Hypothesis 4: Monte-Carlo budgets on both sides, and Sionna's own PathSolver in one call and one receiver per
    call (its shared hash table drops chains of the call's receivers: docs/explanation/ray-tracing.md)."""
    points, rm = grid["points"], ref["rm"]
    for n in args.rm_sweep:
        other, rm_s = _timed(b.radio_map, grid, s, n)
        rows.append(
            _row(
                "samples", f"radio map {n:.0e} samples", ref["red"]["precoded"], other[grid["iy"], grid["ix"]], 0, rm_s
            )
        )
    for n in args.ps_sweep:
        a, ps_s = _timed(b.paths, points, replace(s, samples_per_src=n, max_num_paths_per_src=10_000_000))
        rows.append(_ps_row("samples", f"PathSolver {n:.0e} samples", a, rm, ps_s, 0))
    stock = replace(s, batch_independent=False)
    a, ps_s = _timed(b.paths, points, stock, solver="sionna")
    rows.append(_ps_row("samples", f"Sionna's own PathSolver, {len(points)} receivers in one call", a, rm, ps_s, 0))
    pre = reduce(a)["precoded"]
    rows.append(_row("samples", "  the same against the batch-independent one", pre, ref["red"]["precoded"], ps_s, 0))
    sub = np.arange(0, len(points), args.solo_every)
    solo, ps_s = _timed(lambda: np.concatenate(_padded([b.paths(points[i : i + 1], stock, "sionna") for i in sub])))
    what = f"Sionna's own PathSolver, one receiver per call (every {args.solo_every}th cell)"
    rows.append(_ps_row("samples", what, solo, rm[sub], ps_s, 0))
    rows.append(_row("samples", "  the same cells in one call", pre[sub], rm[sub], 0, 0))
    rows.append(_row("samples", "  the same cells, batch-independent", ref["red"]["precoded"][sub], rm[sub], 0, 0))


def _padded(parts: list[np.ndarray]) -> list[np.ndarray]:
    """Arrays of several calls padded to the widest path count (zeros: no path), ready to concatenate."""
    width = max(x.shape[-1] for x in parts)
    return [np.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, width - x.shape[-1])]) for x in parts]


def main() -> None:
    """Parse, set up one tracer, run each hypothesis' ablation, write JSON + Markdown + PNG."""
    import sys

    args = _parse_args()
    t0 = time.perf_counter()
    spec = load_scene_spec(args.scene, args.variant)
    grid = _grid(spec)
    print(f"{spec.name}: {len(grid['points'])} free cells", flush=True)
    b = Bench(spec)
    s = replace(b.base, samples_per_src=args.ps_samples, batch_size=args.batch)
    b.paths(grid["points"][:8], s)  # the first JIT compile, outside every timed row
    rows: list[dict] = []
    cells = antennas(b, grid, args, s, rows)
    area(b, spec, args, s, rows, cells)
    interactions(b, grid, args, s, rows)
    samples(b, grid, args, s, rows, cells)
    tx = spec.tx
    result = {
        "scene": spec.name,
        "command": "python bench/bench_radiomap.py " + " ".join(sys.argv[1:]),
        "free_cells": len(grid["points"]),
        "ps_samples": args.ps_samples,
        "rm_samples": args.rm_samples,
        "rm_cell_m": grid["cell_m"],
        "plane_z_m": grid["centre"][2],
        "rx_height_m": spec.rx_height_m,
        "max_depth": s.max_depth,
        "tx_array": f"{tx.num_rows}x{tx.num_cols} {tx.pattern} {tx.polarization}, {b.tracer.scene.tx_array.num_ant} "
        "ports",
        "tx_ports": b.tracer.scene.tx_array.num_ant,
        # the ablations' settings (the rows' labels name them; the results page's tables find rows by them)
        "subpoints": args.subpoints,
        "depths": args.depths,
        "rm_sweep": args.rm_sweep,
        "ps_sweep": args.ps_sweep,
        "solo_every": args.solo_every,
        "diffraction": not args.no_diffraction,
        "seconds": round(time.perf_counter() - t0, 1),
        "rows": rows,
        "machine": f"{describe(machine())}, no GPU (LLVM backend)",
        "machine_details": machine(),
        "library_versions": library_versions(),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bench_radiomap.json").write_text(json.dumps(result, indent=2) + "\n")
    md = markdown(result)
    (args.out / "bench_radiomap.md").write_text(md)
    print(md, end="")
    plot(cells, args.out / "bench_radiomap.png", f"{spec.name}: PathSolver against RadioMapSolver per free cell")


if __name__ == "__main__":
    main()
