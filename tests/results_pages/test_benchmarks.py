"""The tables of the speed and ray-tracing pages that one benchmark's JSON makes: each renderer gives the committed
page's block back from a JSON holding its numbers, and a re-run's number lands in it."""


def test_bench_rt_renders_the_ray_tracing_pages_table_from_its_json_alone(pages, tmp_path, capsys):
    text, block = pages.block_of("ray-tracing.md", "bench-rt results/bench_rt_stock.json")
    keys = ("samples_per_src", "seconds", "cells_per_s", "agreement", "found_path_share", "paths_found_vs_reference")
    rows = []
    for cells in pages.rows_of(text, block):
        row = dict(zip(keys, map(pages.num, cells), strict=False))
        for k in ("agreement", "found_path_share", "paths_found_vs_reference"):
            row[k] /= 100
        row["samples_per_src"] = int(row["samples_per_src"])
        rows.append(
            {**row, "median_abs_gain_error_db": pages.num(cells[6]), "speedup_vs_reference": pages.num(cells[7])}
        )
    data = {
        "scene": "cubicle/blueprint",
        "free_cells": 592,
        "max_depth": 5,
        "machine": "2-core CPU, no GPU (LLVM backend)",
        "reference_samples": 1_000_000,
        "reference_path_buffer": 10_000_000,
        "path_buffer": 1_000_000,
        "reference_seconds": 136.6,
        "first_call_seconds_incl_jit": 2.3,
        "rows": rows,
    }
    pages.renders_the_page(tmp_path, capsys, "ray-tracing.md", "bench-rt", data, ("1480.3", "1500.0"))
    md = pages.results_pages.bench("bench_rt.py", "markdown")(data)
    assert "Reference: 1e+06 samples (path buffer 1e+07), 136.6 s (4 cells/s)" in md  # the page's sentence above


def test_bench_threads_renders_the_speed_pages_threads_table(pages, tmp_path, capsys):
    def case(load, threads, each, median, steps):
        return {"load": load, "threads": threads, "wall_s_each": each, "median_wall_s": median,
                "median_steps_per_s": steps, "updates": 100}  # fmt: skip

    data = {
        "scene": "cubicle",
        "preset": "memory-escape-noise",
        "steps": 30_000,
        "rounds": 3,
        "busy_rounds": 1,
        "machine": {},
        "cases": [
            case("idle", 1, [7.93, 7.1, 6.92], 7.1, 4262),
            case("idle", 2, [5.46, 4.33, 5.27], 5.27, 5746),
            case("one busy process", 1, [7.4], 7.4, 4084),
            case("one busy process", 2, [19.1], 19.1, 1580),
        ],
    }
    pages.renders_the_page(tmp_path, capsys, "speed.md", "bench-threads", data, ("7.93", "8.4"))


def test_bench_latency_renders_the_speed_pages_table_without_the_goal_column(pages, tmp_path, capsys):
    text, block = pages.block_of("speed.md", "bench-latency")
    rows = []
    for policy, threads, load, p50, p99, _ in pages.rows_of(text, block):
        for run, (a, b) in enumerate(zip(p50.split(), p99.split(), strict=True)):
            rows.append({"policy": policy, "threads": int(threads), "load": load, "run": run,
                         "p50_ms": float(a), "p99_ms": float(b)})  # fmt: skip
    data = {"scene": "cubicle", "decisions": 1000, "rows": rows, "machine": {"start": {}, "end": {}}}
    pages.renders_the_page(tmp_path, capsys, "speed.md", "bench-latency", data, ("0.057", "0.051"))
    assert "goal met" in pages.results_pages.bench("bench_latency.py", "markdown")(data)  # the flag's default: yes


def test_bench_rl_renders_the_speed_pages_headline_without_the_throughputrows_of(pages, tmp_path, capsys):
    data = {
        "dataset": {"name": "cubicle/blueprint", "synthetic": False},
        "machine": {"torch_threads": 1, "load_1min_before": 0.1},
        "env_steps_per_s": {"gymnasium": 48_300.0, "batched_4096": 17_300_000.0},
        "decision_latency_ms": 0.042,
        "decision_speedup_vs_paper": 400.0,
        "train": {
            "env_steps": 600_064,
            "wall_s": 47.8,
            "speedup_vs_paper": 58.0,
            "goal_met": True,
            "speedup_vs_sb3": 8.1,
        },  # fmt: skip
        "train_robust": {"config": {"aug_obstacles": 10}, "wall_s": 54.1},
        "sb3": {"wall_s_for_budget": 386.0, "env_steps": 466_665, "capped": True, "threads": 1},
        "eval": [],
    }
    pages.renders_the_page(
        tmp_path, capsys, "speed.md", "bench-rl results/bench_rl.json table=1", data, ("47.8", "49.0")
    )
    assert "env steps/s" in pages.results_pages.bench("bench_rl_report.py", "render_markdown")(data)
