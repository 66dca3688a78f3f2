"""Renderers of the benchmarks whose JSON holds a whole table: each calls the benchmark's own renderer, so a page's
block is what the benchmark's .md holds."""

from __future__ import annotations

from renderers.base import Renderer, bench, lines, module

#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "bench-radio": Renderer(
        lambda d, o: bench("bench_radio.py", "markdown")(d),
        'make bench-radio ARGS="--out {stem}" (several runs: python bench/bench_radio.py --merge <their .json> '
        "--out {stem})",
    ),
    "bench-nav": Renderer(
        lambda d, o: bench("bench_nav.py", "markdown")(d),
        'make bench-nav ARGS="--out {dir} --name {name}" (with the scenes and options the page names)',
    ),
    "bench-rl": Renderer(
        lambda d, o: bench("bench_rl_report.py", "render_markdown")(d, throughput=o["throughput"] == "yes"),
        "make bench-rl (results/bench_rl.json; --scene <scene>: results/bench_rl_<scene>.json)",
        flags=("throughput",),
    ),
    "bench-latency": Renderer(
        lambda d, o: bench("bench_latency.py", "markdown")(d, goal=o["goal"] == "yes"),
        'make bench-latency SCENE=<scene> ARGS="--out {dir}" (writes {dir}/bench_latency_<scene>.json)',
        flags=("goal",),
    ),
    "bench-threads": Renderer(
        lambda d, o: bench("bench_threads.py", "markdown")(d),
        'make bench-threads SCENE=<scene> ARGS="--out {dir}" (writes {dir}/bench_threads_<scene>.json)',
    ),
    "bench-rt": Renderer(
        lambda d, o: bench("bench_rt.py", "markdown")(d),
        'make bench-rt ARGS="--out {dir}" (with the options the page names; --scene, --buffer and --stock-solver '
        "name the file: {name}.json)",
    ),
    "bench-moving": Renderer(
        lambda d, o: bench("bench_moving_report.py", "markdown")(d),
        'make bench-moving SCENES=<scene> ARGS="--out {dir}" (writes {dir}/bench_moving_<scene>.json)',
    ),
    "bench-offline-speed": Renderer(
        lambda d, o: bench("bench_offline_speed_report.py", "markdown")(d),
        'make bench-offline-speed ARGS="--out {stem}"',
    ),
    "offline-bench": Renderer(
        lambda d, o: module("dtradar_rl.experiments.offline_report", "markdown")(d),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
    ),
    "offline-bench-scores": Renderer(
        lambda d, o: lines(module("dtradar_rl.experiments.offline_report", "score_table")(d, o["variant"])),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
        ("variant",),
    ),
    "offline-bench-returns": Renderer(
        lambda d, o: lines(module("dtradar_rl.experiments.offline_report", "return_table")(d, o["variant"])),
        "python -m dtradar_rl offline-bench --out {dir} (with the options the page names)",
        ("variant",),
    ),
}
