"""Evaluation rows with their normalised score (0 = uniformly random moves, 100 = the shortest-path expert), so a
results table says how good an agent is on the scale every dataset card, benchmark and paper table uses
(:mod:`dtradar_rl.evaluation.normalized`), not only its raw SPL.

    rows = with_normalized(rows, {ds.name: ds}, pairs=500, seed=2024)   # each row gains "normalized"
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from dtradar_data.core.dataset import Dataset
from dtradar_rl.evaluation.normalized import normalized, reference_scores
from dtradar_rl.task.twins import load_dataset


def with_normalized(
    rows: Sequence[dict[str, Any]],
    datasets: dict[str, Dataset] | None = None,
    *,
    pairs: int,
    seed: int,
    max_steps: int | None = None,
    device: str = "cpu",
) -> list[dict[str, Any]]:
    """``rows`` (``{"dataset", "version", "spl", ...}``, as :func:`~dtradar_rl.evaluation.evaluate.evaluate_twins`
    makes them) each with ``"normalized"``: its SPL against the random and expert references rolled out on the same
    twin, ``pairs``, ``seed`` and step limit the row was evaluated with (the references are cached per twin, so the
    shielded row of a twin costs nothing more). A twin not in ``datasets`` is loaded at the row's version."""
    twins = dict(datasets or {})
    out = []
    for row in rows:
        name, version = row["dataset"], row.get("version")
        if name not in twins:
            twins[name] = load_dataset(f"{name}@{version}" if version else name)
        refs = reference_scores(twins[name], pairs=pairs, seed=seed, max_steps=max_steps, device=device)
        out.append({**row, "normalized": normalized(row["spl"], refs)})
    return out


__all__ = ["with_normalized"]
