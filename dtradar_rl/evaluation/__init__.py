"""Evaluation on seeded pairs of any twin: success, SPL, collisions, decision time, the cross matrix, fixed-pair
inference, and the ``make eval`` / ``cross`` jobs."""

# ``evaluate`` is also the name of a module here, so the function is imported from it (or from ``dtradar_rl``).
from dtradar_rl.evaluation.evaluate import Metrics, cross_matrix, evaluate_twins, spl

__all__ = ["Metrics", "cross_matrix", "evaluate_twins", "spl"]
