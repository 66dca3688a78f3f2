"""The reference scores of a logged dataset's Minari copy: its ``ref_min_score`` / ``ref_max_score``.

Minari defines them on episode returns in the copy's *evaluation* env (``eval_env_spec``, what
``recover_environment(eval_env=True)`` makes): ``minari.get_normalized_score(dataset, returns)`` is
``(returns - ref_min_score) / (ref_max_score - ref_min_score)``. dtradar fills them with the exact references of its
return-based normalised score (:mod:`dtradar_rl.evaluation.returns`) on that env's twin, with the logged reward: the
mean discounted return (γ = :data:`~dtradar_rl.tabular.solver.GAMMA`) of uniformly random moves and of the optimal
policy over the twin's 500 seeded evaluation pairs (seed 2024). So ``100 · get_normalized_score(dataset, J)``, with
``J`` a policy's mean discounted return over those pairs, is :func:`~dtradar_rl.evaluation.returns.return_score`.
Minari runs no policy of its own for them (it would, with an ``expert_policy``). A moving twin's copy has none: the
exact references solve a static twin's MDP, and a moving twin's is in space-time (its Minari metadata leaves them out,
which Minari allows; the dtradar card gives the log's SPL-based normalised score).
"""

from __future__ import annotations

from typing import Any

from dtradar_rl.evaluation.returns import return_references
from dtradar_rl.tabular.solver import GAMMA


def reference_returns(eval_spec: Any) -> dict[str, Any] | None:
    """``{"ref_min_score", "ref_max_score", "references"}`` for the evaluation env spec of a Minari copy; None when
    its twin is a moving one (module docstring)."""
    from dtradar_rl.task.twins import is_synthetic, load_dataset

    kw = eval_spec.kwargs
    dataset, version = kw["dataset"], kw.get("version")
    scene = dataset.split("/")[0]
    ds = load_dataset(dataset if version is None or is_synthetic(scene) else f"{dataset}@{version}")
    if ds.is_moving:
        return None
    refs = return_references(ds, reward=kw.get("reward", "geodesic"), gamma=GAMMA)
    return {
        "ref_min_score": refs["random"],
        "ref_max_score": refs["optimal"],
        "references": {**refs, "twin": f"{dataset}@{version}", "returns": "discounted, from the start"},
    }


__all__ = ["reference_returns"]
