"""Pictures of results: training curves, navigation paths over coverage maps, cross matrices and bars, twin-update
curves (matplotlib, Agg backend; written atomically)."""

from dtradar_rl.viz.plots import plot_curves, plot_matrix, plot_paths

__all__ = ["plot_curves", "plot_matrix", "plot_paths"]
