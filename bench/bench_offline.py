"""Offline-RL benchmark (`make offline-bench` runs the same through `python -m dtradar_rl offline-bench`).

    python bench/bench_offline.py --scene cubicle                      # the full setting: 4 datasets x 6 algorithms x 3
    seeds python bench/bench_offline.py --scene cubicle --n-steps 2000 --steps 50000   # the reduced setting measured in
    the README python bench/bench_offline.py --help

d3rlpy DiscreteCQL, DiscreteBCQ, DiscreteBC, DQN, DoubleDQN and NFQ on every logged behaviour dataset (random,
noisy-shortest, epsilon-greedy from the online DQN, mixture), evaluated with our own rollouts on the blueprint and
dynamic twins beside the online DQN and the behaviour itself; mean ± std over seeds. Writes bench.json, bench.md and
bench.png to results/offline_bench/<scene>/ (see dtradar_rl.experiments.offline_bench).
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
