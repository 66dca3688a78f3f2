"""The tables of docs/results/ray-tracing.md: each renderer gives the committed page's block back from JSONs in the
shape of their writers (bench_rt.py, bench_differential.py, bench_moving.py, bench_radiomap.py, the dataset cards)
holding the page's numbers, and a re-run's number lands in it."""

PAGE = "ray-tracing.md"


def renders_from_runs(pages, tmp_path, capsys, marker: str, runs: list[dict], change: tuple) -> str:
    return pages.renders_runs(tmp_path, capsys, PAGE, marker, runs, change)


def bench_rt_run(rows: list[dict], default: int, city: bool, buffer: int = 1_000_000) -> dict:
    """A bench_rt.py JSON (the fields its renderers read; the cubicle's stock run is the page's first table too)."""
    return {
        "scene": "dallas-q3/blueprint" if city else "cubicle/blueprint",
        "free_cells": 480 if city else 592,
        "max_depth": 5,
        "machine": "2-core CPU, no GPU (LLVM backend)",
        "reference_samples": 300_000 if city else 1_000_000,
        "reference_path_buffer": 10_000_000,
        "reference_seconds": 136.6,
        "first_call_seconds_incl_jit": 2.3,
        "path_buffer": buffer,
        "default_samples_per_src": default,
        "scene_rt_defaults": {"samples_per_src": 100_000, "max_num_paths_per_src": 10_000_000} if city else {},
        "rows": rows,
    }


def rt_row(samples: int, agreement: float, found: float, paths: float, gain: float, cells_per_s: float,
           seconds: float = 1.0, speedup: float = 1.0) -> dict:  # fmt: skip
    return {"samples_per_src": samples, "seconds": seconds, "cells_per_s": cells_per_s, "agreement": agreement,
            "found_path_share": found, "paths_found_vs_reference": paths, "median_abs_gain_error_db": gain,
            "speedup_vs_reference": speedup}  # fmt: skip


def test_both_solvers_side_by_side_come_from_four_bench_rt_runs(pages, tmp_path, capsys):
    def run(samples, cells, default, city):
        rows = []
        for s, cell in zip(samples, cells, strict=True):
            agree, paths, gain, speed = (c.strip(" ()*%dB") for c in cell.split(" / "))
            rows.append(rt_row(s, float(agree) / 100, 1.0, float(paths) / 100, float(gain), float(speed)))
        return bench_rt_run(rows, default, city, 10_000_000 if city else 1_000_000)

    text, block = pages.block_of(PAGE, "ray-tracing-solvers")
    cells = pages.rows_of(text, block)
    _, stock_block = pages.block_of(PAGE, "bench-rt results/bench_rt_stock.json")
    stock = pages.rows_of(text, stock_block)  # the first table's run: its six rows, three of them shown here
    city, indoor = (10_000, 30_000, 100_000), (1_000, 3_000, 10_000)
    runs = [
        run(city, [c[1] for c in cells[:3]], 100_000, True),
        run(city, [c[2] for c in cells[:3]], 100_000, True),
        run(indoor, [c[1] for c in cells[3:]], 10_000, False),
        bench_rt_run(
            [
                rt_row(
                    int(pages.num(r[0])),
                    *(pages.num(c) / 100 for c in r[3:6]),
                    *map(pages.num, (r[6], r[2], r[1], r[7])),
                )
                for r in stock
            ],
            10_000,
            False,
        ),
    ]
    now = renders_from_runs(pages, tmp_path, capsys, "ray-tracing-solvers", runs, (0, "156.1", "160.4"))
    assert "| Dallas Q3 (8 m), 10⁴ | 87.5 % / 48 % / 0.418 dB / 160.4 |" in now


def test_the_outdoor_path_buffers_come_from_one_bench_rt_run_per_buffer(pages, tmp_path, capsys):
    text, block = pages.block_of(PAGE, "ray-tracing-buffers")
    runs = {1_000_000: [], 10_000_000: []}
    for s, buffer, speed, agree, found, paths, gain in pages.rows_of(text, block):
        row = rt_row(int(pages.num(s)), pages.num(agree) / 100, pages.num(found) / 100, pages.num(paths) / 100,
                     pages.num(gain), pages.num(speed))  # fmt: skip
        runs[{"10⁶": 1_000_000, "10⁷": 10_000_000}[buffer]].append(row)
    data = [bench_rt_run(rows, 100_000, True, buffer) for buffer, rows in runs.items()]
    now = renders_from_runs(pages, tmp_path, capsys, "ray-tracing-buffers", data, (1, "68.0", "70.2"))
    assert "| 30,000 | 10⁷ | 70.2 | 90.4 % |" in now


def test_the_differential_retrace_comes_from_each_scenes_bench_differential_json(pages, tmp_path, capsys):
    def scene(name, retraced, free, full_s, diff_s, speedup, agree, gain, parent, seed):
        share = dict(zip(("all", "retraced", "kept"), agree, strict=True))
        return {
            "scene": name, "free_cells": free, "retraced_cells": retraced, "full_s": full_s, "differential_s": diff_s,
            "speedup": speedup,
            "differential_vs_full": {k: {"agreement": a, "gain_median_db": gain[0], "gain_p95_db": gain[1]}
                                     for k, a in share.items()},
            "parent_reused_vs_full": {"agreement": parent}, "full_other_seed_vs_full": {"agreement": seed},
            "machine": "2-core CPU",
        }  # fmt: skip

    runs = [
        scene("cubicle", 449, 579, 3.93, 3.21, 1.22, (0.986, 0.982, 1.0), (0.066, 0.73), 0.972, 0.976),
        scene("meeting", 896, 1247, 8.02, 7.98, 1.0, (0.998, 0.997, 1.0), (0.052, 0.63), 0.997, 0.997),
        scene("dallas-q3", 315, 1894, 85.8, 14.8, 5.8, (0.921, 0.905, 0.924), (0.057, 2.68), 0.907, 0.927),
    ]
    renders_from_runs(pages, tmp_path, capsys, "ray-tracing-differential", runs, (2, "2.68", "2.71"))


def test_the_moving_twins_builds_one_process_and_with_a_helper_come_from_two_bench_moving_runs(pages, tmp_path, capsys):
    def build(helpers, warm, diff, full, speedup):
        return {
            "scene": "cubicle", "snapshots": 60, "helpers": helpers, "first_compile_s": 1.08,
            "goals": {"build_time": {"warm_s": warm}}, "differential_total_s": diff, "full_total_s": full,
            "speedup_total": speedup, "agreement_mean": 1.0, "agreement_min": 1.0,
            "seed_floor": [{"k": 0, "agreement": 0.998}, {"k": 30, "agreement": 0.9983}],
        }  # fmt: skip

    runs = [build(0, 155.31, 147.2, 192.0, 1.304), build(1, 88.02, 79.9, 193.1, 2.417)]
    now = renders_from_runs(pages, tmp_path, capsys, "ray-tracing-moving", runs, (1, "88.02", "160.0"))
    assert "| **155.3 s** (+ 1.1 s) | 160.0 s (+ 1.1 s) |" in now  # the faster build is the one in bold


def test_the_tables_against_sionnas_radio_map_come_from_the_bench_radiomap_json(pages, tmp_path, capsys):
    def row(group, what, median, abs_, p90, ratio, cells=592, **extra):
        return {"group": group, "what": what, "cells": cells, "median_db": median, "median_abs_db": abs_,
                "p90_abs_db": p90, "mean_linear_ratio_db": ratio, "ps_s": 0, "rm_s": 0, **extra}  # fmt: skip

    def inter(what, paths, median, abs_, p90, table):
        return row("interactions", what, median, abs_, p90, -0.3, paths=paths, table_median_db=table)

    rows = [
        row("antennas", "table vs radio map (default precoding)", 2.97, 3.31, 5.93, -6.58, paths=59444),
        row("antennas", "full-pol ports vs radio map (default precoding)", 8.54, 8.54, 12.36, -3.27, paths=59444),
        row("antennas", "precoded vs radio map (default precoding)", -0.09, 0.13, 0.82, -0.31, paths=59444),
        row("antennas", "  step 1: table vs full-pol ports (PathSolver both)", -5.79, 5.79, 8.21, -3.3),
        row("antennas", "  step 2: full-pol ports vs precoded (PathSolver both)", 8.79, 8.79, 12.8, -2.96),
        row("antennas", "dataset's dipole V, port mean vs radio map", 3.4, 4.05, 7.1, -9.72),
        row("antennas", "full-pol ports vs port-averaged radio map", -0.05, 0.06, 0.33, -0.01),
        row("area", "centre point vs 0.5 m cell (as above)", -0.09, 0.13, 0.82, -0.31),
        row("area", "mean of 2x2 points vs 0.5 m cell", -0.04, 0.07, 0.35, -0.0),
        row("area", "mean of 2x2 points vs mean of 2x2 sub-cells", -0.04, 0.05, 0.3, -0.0),
        row("area", "each point vs its 0.25 m sub-cell", -0.05, 0.11, 0.43, -0.0, cells=2368),
        row("area", "LoS only: centre point vs 0.5 m cell", -0.03, 0.05, 2.18, -0.39),
        row("area", "LoS only: mean of 2x2 points vs 0.5 m cell", -0.01, 0.02, 0.45, 0.0),
        inter("LoS only", 582, -0.03, 0.05, 2.18, 7.14),
        inter("LoS + specular, depth 1", 3902, -0.02, 0.07, 1.25, 4.74),
        inter("LoS + specular, depth 2", 13048, -0.04, 0.08, 0.64, 3.68),
        inter("LoS + specular, depth 3", 31148, -0.03, 0.08, 0.73, 3.35),
        inter("LoS + specular, depth 5", 99918, -0.04, 0.07, 0.67, 3.2),
        inter("LoS + refraction, depth 5", 582, -0.03, 0.05, 2.18, 7.14),
        inter("LoS + specular + refraction, depth 5 (datasets)", 59444, -0.09, 0.13, 0.82, 2.97),
        inter("+ diffraction, depth 5", 61906, -0.11, 0.14, 1.14, 2.96),
        row("samples", "radio map 1e+06 samples", -0.12, 0.22, 0.98, -0.32),
        row("samples", "PathSolver 1e+05 samples", -0.05, 0.11, 0.59, -0.31, paths=106735, table_median_db=3.0),
        row("samples", "Sionna's own PathSolver, 592 receivers in one call", -1.57, 1.57, 6.58, -0.69, paths=47819),
        row("samples", "  the same against the batch-independent one", -1.5, 1.5, 6.5, -0.4),
        row(
            "samples",
            "Sionna's own PathSolver, one receiver per call (every 8th cell)",
            -0.07,
            0.09,
            1.36,
            -0.4,
            cells=74,
            paths=6000,
        ),  # fmt: skip
        row("samples", "  the same cells in one call", -1.14, 1.22, 4.41, -0.52, cells=74),
        row("samples", "  the same cells, batch-independent", -0.07, 0.09, 1.36, -0.4, cells=74),
    ]
    data = {
        "scene": "cubicle/blueprint", "command": "python bench/bench_radiomap.py --scene cubicle", "free_cells": 592,
        "ps_samples": 10_000, "rm_samples": 10_000_000, "rm_cell_m": 0.5, "plane_z_m": 1.0, "rx_height_m": 1.0,
        "max_depth": 5, "tx_ports": 32, "subpoints": 2, "depths": [1, 2, 3, 5], "rm_sweep": [1_000_000],
        "ps_sweep": [100_000], "solo_every": 8, "diffraction": True, "seconds": 142.0, "rows": rows,
        "machine": "2-core Intel Xeon",
    }  # fmt: skip
    marker = "ray-tracing-radiomap results/bench_radiomap/bench_radiomap.json"
    pages.renders_the_page(tmp_path, capsys, PAGE, f"{marker} table=1", data, ("5.93", "6.04"))
    pages.renders_the_page(tmp_path, capsys, PAGE, f"{marker} table=2", data, ("0.64", "0.66"))
    md = pages.results_pages.bench("bench_radiomap_report.py", "markdown")(data)
    assert "## Summary" in md and "| ablation (cubicle," in md and "## samples" in md  # the benchmark's own report


def test_the_build_times_come_from_the_dataset_cards_of_the_build(pages, tmp_path, capsys):
    def card(name, free, with_paths, paths, seconds):
        stats = {"num_free": free, "num_with_paths": with_paths, "num_paths_total": paths, "trace_seconds": seconds}
        return {"tag": "v0", "history": [], "meta": {"name": name, "stats": stats}}

    runs = [
        card("dallas-q1/blueprint", 1957, 1957, 49511, 80.2),
        card("dallas-q2/blueprint", 1527, 1365, 18342, 44.3),
        card("dallas-q3/blueprint", 1950, 1935, 46281, 75.9),
        card("dallas-q4/blueprint", 1968, 1946, 54687, 68.4),
        card("dallas-q3/dynamic", 1894, 1879, 43457, 70.1),
    ]
    now = renders_from_runs(pages, tmp_path, capsys, "ray-tracing-build-times", runs, (1, "18342", "18401", "18 401"))
    assert "| `dallas-q2/blueprint` | 1 527 | 1 365 (89.4 %) | 18 401 | 44 s |" in now
