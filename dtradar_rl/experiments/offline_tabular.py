"""The offline benchmark's tabular rows: each logged dataset's ceiling and the tabular batch learners on it.

For one logged dataset (:mod:`dtradar_rl.tabular.batch`): the empirical model of its moves, the **data ceiling** on
the twin it was logged on (the best SPL and return of any policy that uses only logged (cell, action) pairs, with the
true cell), and every learner of :data:`~dtradar_rl.tabular.batch.LEARNERS` as a table over the blueprint's cells and
the evaluation pairs' targets. A learner's table acts as a robot would, through
:class:`~dtradar_rl.tabular.table_policy.TablePolicy`: it localises by the nearest blueprint fingerprint and looks up
its move, rolled out like the deep agents on the same seeded pairs of every evaluated twin (so its SPL-normalised
score sits beside theirs), and its return-based normalised score is exact (the table composed with the fingerprint
localisation of that twin is again a table, evaluated by :func:`~dtradar_rl.tabular.evaluation.policy_values`).
A deterministic table's episodes are followed move by move instead of rolled out in the env (the same episodes, tested;
a tenth of the time), a stochastic one's (Π_b-SPIBB) are rolled out.

Beside them, CE and VI-LCB **with senses** (``ce-senses``, ``lcb-senses``; :mod:`dtradar_rl.tabular.sensing`): the
same tables followed by a robot that carries its belief along its own moves, forbids the moves it senses or bumps
into as blocked and re-plans on the same empirical model; their return-based score is the mean discounted return of
those episodes (exact: the episodes are deterministic).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from dtradar_data.core.dataset import Dataset
from dtradar_rl.evaluation.evaluate import metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.evaluation.normalized import DEFAULT_SEED, normalized, reference_scores
from dtradar_rl.evaluation.returns import pair_values, return_references, return_score
from dtradar_rl.tabular.batch import LEARNERS, NAMES, BatchConfig, ceiling, empirical_model, learn
from dtradar_rl.tabular.evaluation import follow, path_metrics, policy_values
from dtradar_rl.tabular.fingerprints import Tracker, localisation
from dtradar_rl.tabular.sensing import SENSING, SUFFIX, WINDOW, follow_sensing, radio_flags
from dtradar_rl.tabular.solver import TabularMDP
from dtradar_rl.tabular.table_policy import TablePolicy
from dtradar_rl.task.twins import load_dataset


def grid_table(tab: TabularMDP, table: np.ndarray) -> np.ndarray:
    """A learner's ``[K, N(, 4)]`` table (states in ``tab.cells`` order) as TablePolicy's ``[H*W, K(, 4)]`` (a
    blocked cell's row is never read: no robot is believed to stand on one)."""
    out = np.zeros((tab.mdp.num_cells, *table.shape[:1], *table.shape[2:]), table.dtype)
    if table.ndim == 3:
        out[...] = 0.25
    out[tab.cells] = np.swapaxes(table, 0, 1)
    return out


def localised_table(tab_bp: TabularMDP, tab: TabularMDP, loc: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``table`` (over blueprint states) as the table over ``tab``'s states that a robot localising with ``loc``
    (true grid cell -> believed blueprint cell) follows."""
    return table[:, tab_bp.state_of[loc[tab.cells]]]


#: Every tabular learner column of a dataset's row, in order: the tables, then the tables with senses.
COLUMNS: tuple[str, ...] = (*LEARNERS, *(n + SUFFIX for n in SENSING))
COLUMN_NAMES = {**NAMES, **{n + SUFFIX: f"{NAMES[n]} + senses" for n in SENSING}}


def _with_senses(blueprint, tab_bp, twin, name, model, table, targets, pairs, cfg, refs):
    """Scores of learner ``name``'s table followed by a sensing, re-planning robot (module docstring) on ``twin``."""
    tab = TabularMDP.from_dataset(twin)
    paths = follow_sensing(
        name,
        model,
        table,
        np.searchsorted(targets, pairs[:, 1]),
        tab,
        localisation(blueprint, twin),
        radio_flags(twin),
        radio_flags(blueprint),
        pairs[:, 0],
        pairs[:, 1],
        cfg=cfg,
        tracker=Tracker(blueprint, twin, WINDOW),
    )
    m = path_metrics(paths)
    return {
        "return_normalized": return_score(float(paths["returns"].mean()), refs),
        "success_rate": float(m["success_rate"]),
        "spl": float(m["spl"]),
        "collisions": float(m["collisions"]),
        "replans": float(paths["replans"].mean()),
    }


def _on_twin(blueprint: Dataset, tab_bp: TabularMDP, twin: Dataset, table, targets, pairs, model, gamma, refs, policy):
    """Scores of ``table`` on ``twin``'s ``pairs``, localising by fingerprint: the return-based score exactly (the
    table composed with the twin's localisation is a table); success, SPL and collisions by following it (a
    deterministic table: exactly what a rollout gives) or by rolling ``policy`` out (a stochastic one)."""
    tab = TabularMDP.from_dataset(twin)
    loc = localisation(blueprint, twin)
    cols = np.unique(pairs[:, 1])
    rows = np.searchsorted(targets, cols)
    seen = localised_table(tab_bp, tab, loc, table[rows])
    values = policy_values(tab, seen, cols, model.reward, gamma)
    if seen.ndim == 2:
        m = path_metrics(
            follow(tab, seen, np.searchsorted(cols, pairs[:, 1]), pairs[:, 0], pairs[:, 1], tab.mdp.max_steps)
        )
    else:
        m = metrics_from_rollouts(rollout(policy, twin, pairs)).to_dict()
    return {
        "return_normalized": return_score(pair_values(tab, values, cols, pairs).mean(), refs),
        "success_rate": float(m["success_rate"]),
        "spl": float(m["spl"]),
        "collisions": float(m["collisions"]),
    }


def tabular_rows(
    logged,
    twins: dict[str, Dataset],
    refs: dict[str, dict[str, float]],
    *,
    pairs: int = 500,
    cfg: BatchConfig | None = None,
    device: str = "cpu",  # noqa: ARG001  (kept for the benchmark's call; tables act on the CPU)
) -> dict[str, Any]:
    """``{"coverage", "model_s", "ceiling", <learner>: {"learn_s", <variant>: scores}}`` for one logged dataset;
    ``twins`` maps variant -> twin (the blueprint first: the data's own), ``refs`` variant -> SPL references."""
    cfg = (cfg or BatchConfig()).validate()
    blueprint = twins["blueprint"]
    tab = TabularMDP.from_dataset(blueprint)
    t0 = time.perf_counter()
    model = empirical_model(logged, tab)
    out: dict[str, Any] = {"coverage": model.coverage(), "model_s": time.perf_counter() - t0, "reward": model.reward}
    eval_pairs = {v: sample_eval_pairs(ds, pairs, DEFAULT_SEED) for v, ds in twins.items()}
    ret_refs = {v: return_references(ds, reward=model.reward, gamma=cfg.gamma, pairs=pairs) for v, ds in twins.items()}
    out["return_references"] = ret_refs

    c = ceiling(model, eval_pairs["blueprint"], cfg)
    rows = np.searchsorted(c["targets"], eval_pairs["blueprint"][:, 1])
    j = c["values"][rows, tab.states(eval_pairs["blueprint"][:, 0])].mean()
    out["ceiling"] = {
        "seconds": c["seconds"],
        "blueprint": {
            "normalized": normalized(c["spl"], refs["blueprint"]),
            "return_normalized": return_score(j, ret_refs["blueprint"]),
            "success_rate": c["success_rate"],
            "spl": c["spl"],
        },
    }
    targets = np.unique(np.concatenate([p[:, 1] for p in eval_pairs.values()]))
    tables = {}
    for name in LEARNERS:
        t1 = time.perf_counter()
        table = tables[name] = learn(name, model, targets, cfg)
        row: dict[str, Any] = {"learn_s": time.perf_counter() - t1}
        policy = TablePolicy(blueprint, grid_table(tab, table), targets=targets, name=f"tabular {name}")
        for v, ds in twins.items():
            scores = _on_twin(blueprint, tab, ds, table, targets, eval_pairs[v], model, cfg.gamma, ret_refs[v], policy)
            row[v] = {"normalized": normalized(scores["spl"], refs[v]), **scores}
        row["seconds"] = time.perf_counter() - t1
        out[name] = row
    for name in SENSING:
        t1 = time.perf_counter()
        row = {"learn_s": out[name]["learn_s"]}
        for v, ds in twins.items():
            scores = _with_senses(
                blueprint, tab, ds, name, model, tables[name], targets, eval_pairs[v], cfg, ret_refs[v]
            )
            row[v] = {"normalized": normalized(scores["spl"], refs[v]), **scores}
        row["seconds"] = time.perf_counter() - t1
        out[name + SUFFIX] = row
    out["seconds"] = time.perf_counter() - t0
    return out


def twins_by_variant(
    scene: str, twins: dict[str, Dataset], refs: dict[str, dict[str, float]], pairs: int
) -> tuple[dict[str, Dataset], dict[str, dict[str, float]]]:
    """``twins`` (by name) by variant, the blueprint first (loaded when it is not evaluated: the logs' own twin), and
    each one's SPL references (the blueprint's measured here when it is not evaluated)."""
    by_variant = {name.split("/")[1]: ds for name, ds in twins.items()}
    if "blueprint" not in by_variant:
        by_variant = {"blueprint": load_dataset(f"{scene}/blueprint"), **by_variant}
    return by_variant, {v: refs[v] if v in refs else reference_scores(ds, pairs=pairs) for v, ds in by_variant.items()}


def tabular_section(
    scene: str,
    logged: dict[str, Any],
    twins: dict[str, Dataset],
    refs: dict[str, dict[str, float]],
    *,
    pairs: int = 500,
    say=lambda *a, **k: None,
) -> dict[str, Any]:
    """:func:`tabular_rows` of every logged dataset (``{behaviour: LoggedDataset}``) of ``scene``; ``twins`` maps
    ``<scene>/<variant>`` to the evaluated twins, ``refs`` variant to their SPL references (the blueprint's are
    measured here when it is not evaluated)."""
    by_variant, refs = twins_by_variant(scene, twins, refs, pairs)
    out = {}
    for beh, data in logged.items():
        row = out[beh] = tabular_rows(data, by_variant, refs, pairs=pairs)
        say(
            f"tabular on {beh}: ceiling {row['ceiling']['blueprint']['normalized']:.1f}, "
            + ", ".join(
                f"{COLUMN_NAMES[n]} " + "/".join(f"{row[n][v]['normalized']:.1f}" for v in by_variant if v in row[n])
                for n in COLUMNS
            )
            + f" ({row['seconds']:.1f} s)"
        )
    return out


__all__ = [
    "COLUMNS",
    "COLUMN_NAMES",
    "grid_table",
    "localised_table",
    "tabular_rows",
    "tabular_section",
    "twins_by_variant",
]
