"""Evaluation on seeded pairs of any twin: success, SPL, collisions, decision time, the cross matrix, fixed-pair
inference, and the ``make eval`` / ``cross`` jobs."""

from dtradar_rl.evaluation.evaluate import Metrics, cross_matrix, evaluate, evaluate_twins, spl

__all__ = ["Metrics", "cross_matrix", "evaluate", "evaluate_twins", "spl"]
