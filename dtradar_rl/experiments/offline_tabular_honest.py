"""The offline benchmark's tabular rows with an honest sensing: each learnt table followed through the filter.

The tabular batch learners (:mod:`dtradar_rl.tabular.batch`: CE, VI-LCB, Π_b-SPIBB) learn one table per logged
dataset from its cells and moves, for the evaluation pairs' targets, as in the privileged benchmark
(:mod:`dtradar_rl.experiments.offline_tabular`). Here a robot follows its table without being told its cell: through
the default agent's localisation filter, its belief voting for a move, CE and VI-LCB learnt again without the
obstacles it senses (:class:`~dtradar_rl.tabular.filter_table.FilterTablePolicy`), rolled out on the same seeded
pairs and under the same receiver noise as the deep learners. Their columns are ``<learner>-filter``. No data ceiling
(it is defined on the true cell) and no exact return-based score (the filter's belief is not a table): the
SPL-normalised score, success, SPL and collisions.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.agents.radio_filter import FilterConfig
from dtradar_rl.evaluation.evaluate import evaluate, sample_eval_pairs
from dtradar_rl.evaluation.normalized import DEFAULT_SEED, normalized
from dtradar_rl.experiments.offline_tabular import grid_table, twins_by_variant
from dtradar_rl.tabular.batch import LEARNERS, NAMES, BatchConfig, empirical_model, learn
from dtradar_rl.tabular.filter_table import FilterTablePolicy
from dtradar_rl.tabular.sensing import SENSING
from dtradar_rl.tabular.solver import TabularMDP

#: The suffix of a learner's column with an honest sensing.
FILTER_SUFFIX = "-filter"
#: Every column of a dataset's row, in order.
HONEST_COLUMNS: tuple[str, ...] = tuple(n + FILTER_SUFFIX for n in LEARNERS)
HONEST_COLUMN_NAMES = {n + FILTER_SUFFIX: f"{NAMES[n]} + filter" for n in LEARNERS}


def honest_tabular_rows(
    logged,
    twins: dict[str, Dataset],
    refs: dict[str, dict[str, float]],
    *,
    scene: str,
    sensing: str,
    noise: str,
    pairs: int = 500,
    cfg: BatchConfig | None = None,
    device: str = "cpu",
) -> dict[str, Any]:
    """``{"coverage", "model_s", "reward", <learner>-filter: {"learn_s", "seconds", <variant>: scores}}`` for one
    logged dataset; ``twins`` maps variant -> twin (the blueprint first), ``refs`` variant -> SPL references."""
    cfg = (cfg or BatchConfig()).validate()
    blueprint = twins["blueprint"]
    tab = TabularMDP.from_dataset(blueprint)
    t0 = time.perf_counter()
    model = empirical_model(logged, tab)
    out: dict[str, Any] = {"coverage": model.coverage(), "model_s": time.perf_counter() - t0, "reward": model.reward}
    targets = np.unique(np.concatenate([sample_eval_pairs(ds, pairs, DEFAULT_SEED)[:, 1] for ds in twins.values()]))
    filter_cfg = FilterConfig(scene, sensing, noise)
    for name in LEARNERS:
        t1 = time.perf_counter()
        table = learn(name, model, targets, cfg)
        row: dict[str, Any] = {"learn_s": time.perf_counter() - t1}
        replan = (name, model, cfg) if name in SENSING else None
        policy = FilterTablePolicy(
            blueprint,
            grid_table(tab, table),
            targets,
            HONEST_COLUMN_NAMES[name + FILTER_SUFFIX],
            filter_cfg,
            device,
            replan=replan,
        )
        for v, ds in twins.items():
            policy.meta["stats"] = {}
            m, _ = evaluate(policy, ds, pairs=pairs, seed=DEFAULT_SEED, latency=False, device=device, noise=noise)
            row[v] = {
                "normalized": normalized(m.spl, refs[v]),
                "success_rate": float(m.success_rate),
                "spl": float(m.spl),
                "collisions": float(m.collisions),
                "replans": policy.meta["stats"].get("replans", 0) / max(pairs, 1),
            }
        row["seconds"] = time.perf_counter() - t1
        out[name + FILTER_SUFFIX] = row
    out["seconds"] = time.perf_counter() - t0
    return out


def honest_tabular_section(
    scene: str,
    logged: dict[str, Any],
    twins: dict[str, Dataset],
    refs: dict[str, dict[str, float]],
    *,
    sensing: str,
    noise: str,
    pairs: int = 500,
    device: str = "cpu",
    say=lambda *a, **k: None,
) -> dict[str, Any]:
    """:func:`honest_tabular_rows` of every logged dataset (``{behaviour: LoggedDataset}``) of ``scene``; ``twins``
    maps ``<scene>/<variant>`` to the evaluated twins, ``refs`` variant to their SPL references."""
    by_variant, refs = twins_by_variant(scene, twins, refs, pairs)
    out = {}
    for beh, data in logged.items():
        row = out[beh] = honest_tabular_rows(
            data, by_variant, refs, scene=scene, sensing=sensing, noise=noise, pairs=pairs, device=device
        )
        say(
            f"tabular through the filter on {beh}: "
            + ", ".join(
                f"{HONEST_COLUMN_NAMES[c]} " + "/".join(f"{row[c][v]['normalized']:.1f}" for v in by_variant)
                for c in HONEST_COLUMNS
            )
            + f" ({row['seconds']:.1f} s)"
        )
    return out


__all__ = ["FILTER_SUFFIX", "HONEST_COLUMNS", "HONEST_COLUMN_NAMES", "honest_tabular_rows", "honest_tabular_section"]
