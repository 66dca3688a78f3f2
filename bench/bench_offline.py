"""Offline-RL benchmark (`make offline-bench` runs the same through `python -m dtradar_rl offline-bench`).

    python bench/bench_offline.py --scene cubicle                   # the default: 5 families x 6 algorithms x 3 seeds
    python bench/bench_offline.py --scene cubicle --n-steps 2000    # a shorter budget
    python bench/bench_offline.py --help

d3rlpy DiscreteCQL, DiscreteBCQ, DiscreteBC, DQN, DoubleDQN and NFQ on every dataset family (random, expert, medium,
medium-replay, mixed) logged on the blueprint twin, evaluated with our own rollouts on the blueprint and dynamic twins
on the normalised scale (0 random, 100 shortest-path expert) beside the behaviour itself; mean ± std over seeds.
Writes bench.json, bench.md, bench.png and bench_fqe.png to results/offline_bench/<scene>/ (see
dtradar_rl.experiments.offline_bench).
"""

from __future__ import annotations

import sys

import tyro

from dtradar_data.core.boundary import run_cli
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench


def _run(argv: list[str]) -> int:
    run_bench(tyro.cli(OfflineBenchConfig, args=argv).validate())
    return 0


if __name__ == "__main__":
    sys.exit(run_cli(_run, sys.argv[1:]))
