"""Experiments built on the library: the paper's tables and figures (``make paper``), twin-update curves
(``make adapt``), seed sweeps (``make sweep``) and the offline-RL benchmark (``make offline-bench``)."""

from dtradar_rl.experiments.adapt import AdaptConfig, adapt
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench
from dtradar_rl.experiments.paper import PaperConfig, run_paper
from dtradar_rl.experiments.sweep import SweepConfig, sweep

__all__ = [
    "AdaptConfig",
    "OfflineBenchConfig",
    "PaperConfig",
    "SweepConfig",
    "adapt",
    "run_bench",
    "run_paper",
    "sweep",
]
