"""Experiments built on the library: the paper's tables and figures (``make paper``), twin-update curves
(``make adapt``), seed sweeps (``make sweep``) and the offline-RL benchmark (``make offline-bench``)."""

# Only names that no module of this package has (``adapt`` and ``sweep`` are modules here; their functions are
# imported from them), so ``dtradar_rl.experiments.sweep`` always means the module.
from dtradar_rl.experiments.adapt import AdaptConfig
from dtradar_rl.experiments.offline_bench import OfflineBenchConfig, run_bench
from dtradar_rl.experiments.paper import PaperConfig, run_paper
from dtradar_rl.experiments.sweep import SweepConfig

__all__ = ["AdaptConfig", "OfflineBenchConfig", "PaperConfig", "SweepConfig", "run_bench", "run_paper"]
