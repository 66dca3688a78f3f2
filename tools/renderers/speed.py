"""Renderers of the speed page's tables that no other registry has: ``make bench-rl``'s env-only throughput and its
SB3 comparison of a run beside the default one (each the benchmark's own function, in bench/bench_rl_report.py)."""

from __future__ import annotations

from renderers.base import Renderer, bench

#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "speed-env": Renderer(
        lambda d, o: bench("bench_rl_report.py", "env_table")(d),
        "python bench/bench_rl.py --env-only --threads 1 --out {dir} (writes {dir}/bench_rl_env.json)",
    ),
    "speed-sb3": Renderer(
        lambda d, o: bench("bench_rl_report.py", "sb3_table")(d),
        "python bench/bench_rl.py --no-robust --out {dir} --name {name}",
    ),
}
