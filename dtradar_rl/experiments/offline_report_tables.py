"""The offline results page's tables that set several benchmarks' ``bench.json`` side by side (docs/results/offline.md):
the default benchmark beside the earlier defaults, relabelled against not, the memory window against memoryless, the
OGBench-style families, more updates, bf16. Pure functions of the JSON objects that
:func:`dtradar_rl.experiments.offline_bench.run_bench` writes (in the table's order), like
:mod:`dtradar_rl.experiments.offline_report`'s tables of one benchmark; tools/renderers/offline.py registers them.

A "best deep learner" cell gives, on each twin, the highest mean normalised score of any algorithm (mean ± std over
the seeds; one seed: the score alone), the two twins' best chosen independently, with the algorithms shown where a
table names them (every algorithm whose mean reads the same to one decimal).
"""

from __future__ import annotations

import re
from typing import Any

from dtradar_rl.experiments.offline_report import _pm, best_per_dataset, score_table, tabular_score

Result = dict[str, Any]
#: The twins every cell gives, blueprint first.
TWINS = ("blueprint", "dynamic")


def scene_title(scene: str) -> str:
    """How the page names a scene in prose: ``dallas-q3`` -> ``Dallas Q3``, others as they are."""
    m = re.fullmatch(r"(dallas|munich|boston)-q(\d)", scene)
    return f"{m.group(1).capitalize()} Q{m.group(2)}" if m else scene


def _minus(text: str) -> str:
    """Negative numbers with the typographic minus (a lone ``-``, a missing value, stays)."""
    return re.sub(r"-(?=\d)", "−", text)


def _one(x: float | None) -> str:
    return "-" if x is None else _minus(f"{x:.1f}")


def _thousands(n: float) -> str:
    return f"{n:,.0f}".replace(",", " ")


def short(name: str) -> str:
    """An algorithm as a cell names it: d3rlpy's name without ``Discrete`` (``DiscreteBCQ`` -> ``BCQ``)."""
    return name.removeprefix("Discrete")


def scene_of(result: Result) -> str:
    return result["config"]["scene"]


def best(result: Result, beh: str, variant: str) -> tuple[dict[str, float] | None, list[str]]:
    """The best mean normalised score of ``beh``'s deep learners on ``variant`` (its mean/std/n) and the names of the
    algorithms whose mean reads the same to one decimal, in the table's order."""
    top = best_per_dataset(result, variant).get(beh)
    if top is None:
        return None, []
    m = top[variant]["normalized"]
    names = [
        short(result["algorithms"][e["algorithm"]])
        for e in result["summary"]
        if e["behaviour"] == beh
        and "normalized" in (e.get(variant) or {})
        and f"{e[variant]['normalized']['mean']:.1f}" == f"{m['mean']:.1f}"
    ]
    return m, names


def best_cell(result: Result, beh: str, named: tuple[str, ...] = ("blueprint",)) -> str:
    """``80.0 ± 0.5 (BCQ) / 75.5 ± 1.2``: the best deep learner on each twin, the algorithms named on the twins of
    ``named``; ``-`` where no algorithm ran on ``beh``."""
    cells = []
    for v in TWINS:
        m, names = best(result, beh, v)
        if m is None:
            return "-"
        cells.append(_minus(_pm(m, "{:.1f}")) + (f" ({', '.join(names)})" if v in named else ""))
    return " / ".join(cells)


def best_mean(result: Result, beh: str, variant: str) -> float | None:
    m, _ = best(result, beh, variant)
    return None if m is None else m["mean"]


def behaviour_cell(result: Result, beh: str) -> str:
    """The behaviour itself rolled out on both twins, ``-`` where it is no single policy (``medium-replay``)."""
    ev = (result["datasets"].get(beh) or {}).get("eval") or {}
    if not all(v in ev for v in TWINS):
        return "-"
    return " / ".join(_one(ev[v].get("normalized")) for v in TWINS)


def tabular_cell(result: Result, beh: str, column: str, twins: tuple[str, ...] = TWINS) -> str:
    """A tabular learner's (or the ceiling's) normalised score on ``twins``, ``-`` where it did not run."""
    xs = [tabular_score(result, beh, column, v) for v in twins]
    return "-" if any(x is None for x in xs) else " / ".join(_one(x) for x in xs)


def run_label(cfg: dict[str, Any]) -> str:
    """``relabelled, senses `auto` (default)``: how a benchmark's goals and senses were set (runs from before
    either option: the logged targets, memoryless)."""
    relabel, senses = cfg.get("relabel", "none"), cfg.get("senses", "none")
    goals = "no relabelling" if relabel == "none" else "relabelled"
    seen = "memoryless" if senses == "none" else f"senses `{senses}`"
    return f"{goals}, {seen}" + (" (default)" if (relabel, senses) == ("auto", "auto") else "")


def _senses(cfg: dict[str, Any]) -> str:
    """``memoryless``, ``memory`` or ``senses `auto```: what a benchmark's deep learners observed."""
    senses = cfg.get("senses", "none")
    return {"none": "memoryless", "memory": "memory"}.get(senses, f"senses `{senses}`")


def _row(cells: list[str]) -> str:
    """A table row; an empty cell is written ``| |``."""
    return "|" + "".join(f" {c} |" if c else " |" for c in cells)


def _head(cells: list[str]) -> list[str]:
    return [_row(cells), "|" + "---|" * len(cells)]


def _behaviours(results: list[Result]) -> list[str]:
    return list(dict.fromkeys(b for r in results for b in r["datasets"]))


def logged_table(result: Result) -> str:
    """The logged families a benchmark trained on (``datasets`` of its ``bench.json``: logged, or reused from ``make
    log``): steps, episodes, the behaviour rolled out and its logged episodes on the blueprint's normalised scale."""
    robots = result["config"].get("num_envs", 256)
    lines = _head(
        [
            "dataset",
            "steps",
            "episodes",
            "normalised score, rolled out",
            "normalised score, logged episodes",
        ]
    )
    for d in result["datasets"].values():
        ev = (d.get("eval") or {}).get("blueprint")
        rolled = "— (no single policy)" if ev is None else _one(ev.get("normalized"))
        logged = _one(d.get("logged_score"))
        if ev is None:  # a replay buffer: its episodes are those its robots finished in their share of the steps
            logged += f" (finished episodes: {d['steps'] / robots:.0f} steps per robot)"
        lines.append(_row([f"`{d['name']}`", _thousands(d["steps"]), _thousands(d["episodes"]), rolled, logged]))
    return "\n".join(lines) + "\n"


def defaults_table(results: list[Result], lost: bool = True) -> str:
    """The default benchmark (the last of ``results``) beside earlier ones on the same scene: the behaviour, the best
    deep learner of each (the default's algorithms named), what the default's best loses on the dynamic twin
    (``lost``) and the tabular CE + senses of the default."""
    *earlier, last = results
    head = ["dataset", "behaviour itself", *(run_label(r["config"]) for r in results)]
    head += ["lost on the dynamic twin"] * lost + ["CE + senses"]
    lines = _head(head)
    for beh in last["datasets"]:
        cells = [beh, behaviour_cell(last, beh), *(best_cell(r, beh, ()) for r in earlier), best_cell(last, beh)]
        if lost:
            bp, dy = best_mean(last, beh, "blueprint"), best_mean(last, beh, "dynamic")
            cells.append("-" if bp is None or dy is None else _one(bp - dy))
        lines.append(_row([*cells, tabular_cell(last, beh, "ce-senses")]))
    return "\n".join(lines) + "\n"


def relabelling_table(results: list[Result]) -> str:
    """The best deep learner of benchmarks without and with goal relabelling, a column each (the relabelled ones'
    algorithms named)."""
    relabelled = [r["config"].get("relabel", "none") != "none" for r in results]
    head = [
        f"{scene_title(scene_of(r))}, {'relabelled' if x else 'not relabelled'}" for r, x in zip(results, relabelled)
    ]
    lines = _head(["dataset", *head])
    for beh in _behaviours(results):
        cells = [best_cell(r, beh, ("blueprint",) if x else ()) for r, x in zip(results, relabelled, strict=True)]
        lines.append(_row([beh, *cells]))
    return "\n".join(lines) + "\n"


def _groups(results: list[Result]) -> list[list[Result]]:
    """``results`` grouped by scene, in order."""
    groups: dict[str, list[Result]] = {}
    for r in results:
        groups.setdefault(scene_of(r), []).append(r)
    return list(groups.values())


def _seed_run(result: Result, beh: str, algo: str, seed: int) -> dict[str, Any] | None:
    return next(
        (x for x in result["runs"] if (x["behaviour"], x["algorithm"], x["seed"]) == (beh, algo, seed)),
        None,
    )


def senses_table(results: list[Result]) -> str:
    """One seed's runs, memoryless against the memory window: per scene (its benchmarks in order), a row per dataset
    and benchmark, a column per algorithm; the best blueprint score of each dataset in bold."""
    algos = results[-1]["algorithms"]
    lines = _head(["dataset", *algos.values()])
    for group in _groups(results):
        seed = group[-1]["config"]["seeds"][0]
        for beh in group[-1]["datasets"]:
            rows = []
            for r in group:
                runs = [_seed_run(r, beh, a, seed) for a in algos]
                rows.append((r, [None if x is None else [x[v]["normalized"] for v in TWINS] for x in runs]))
            scores = [(s[0], i, j) for i, (_, ss) in enumerate(rows) for j, s in enumerate(ss) if s is not None]
            top = max(scores, key=lambda t: t[0], default=None)
            for i, (r, ss) in enumerate(rows):
                cells = ["-" if s is None else " / ".join(_one(x) for x in s) for s in ss]
                if top is not None and top[1] == i:  # the best blueprint score: its whole cell in bold
                    cells[top[2]] = f"**{cells[top[2]]}**"
                lines.append(_row([f"{scene_title(scene_of(r))} {beh}, {_senses(r['config'])}", *cells]))
    return "\n".join(lines) + "\n"


def ogbench_table(results: list[Result]) -> str:
    """The OGBench-style families per scene: a scene's benchmarks merged (the deep learners of one, the tables of
    another): the behaviour, the best deep learner (named on both twins), CE and VI-LCB with senses, the ceiling."""
    lines = _head(["family", "behaviour itself", "best deep learner", "CE + senses", "VI-LCB + senses", "data ceiling"])
    for group in _groups(results):
        deep = next((r for r in group if r["summary"]), group[0])
        tables = next((r for r in group if r.get("tabular")), group[0])
        for beh in _behaviours(group):
            own = next((r for r in group if (r["datasets"].get(beh) or {}).get("eval")), group[0])
            cells = [
                f"{scene_of(group[0])} {beh}",
                behaviour_cell(own, beh),
                best_cell(deep, beh, TWINS),
                tabular_cell(tables, beh, "ce-senses"),
                tabular_cell(tables, beh, "lcb-senses"),
                tabular_cell(tables, beh, "ceiling", ("blueprint",)),
            ]
            lines.append(_row(cells))
    return "\n".join(lines) + "\n"


def best_learners_table(results: list[Result]) -> str:
    """The best deep learner of benchmarks on the same families, a column each labelled by its senses (the
    algorithms named on the blueprint)."""
    lines = _head(["family", *(f"best deep learner, {_senses(r['config'])}" for r in results)])
    for beh in _behaviours(results):
        lines.append(_row([f"{scene_of(results[0])} {beh}", *(best_cell(r, beh) for r in results)]))
    return "\n".join(lines) + "\n"


def updates_table(results: list[Result]) -> str:
    """Benchmarks that differ in their updates per run, a column each: a row per dataset and algorithm that every
    one of them trained (mean ± std over seeds, ``-`` where a benchmark left the dataset out)."""
    algos = [a for a in results[-1]["algorithms"] if all(a in r["algorithms"] for r in results)]
    steps = [r["config"]["n_steps"] for r in results]
    lines = _head([scene_title(scene_of(results[0])), f"{_thousands(steps[0])} updates", *map(_thousands, steps[1:])])
    for beh in _behaviours(results):
        for a in algos:
            cells = []
            for r in results:
                e = next((e for e in r["summary"] if (e["behaviour"], e["algorithm"]) == (beh, a)), None)
                m = [((e or {}).get(v) or {}).get("normalized") for v in TWINS]
                cells.append("-" if None in m else " / ".join(_minus(_pm(x, "{:.1f}")) for x in m))
            lines.append(_row([f"{beh}, {results[-1]['algorithms'][a]}", *cells]))
    return "\n".join(lines) + "\n"


def precision_label(result: Result) -> str:
    """How a benchmark's updates ran: ``fp32, batch 256 (default)``, or with ``--precision auto`` the algorithms it
    put in bf16 and their batch (each run records what its precision and batch resolved to)."""
    cfg = result["config"]
    precision, batch = cfg.get("precision", "fp32"), cfg.get("batch_size", 256)
    bf16 = [r for r in result["runs"] if r.get("precision") == "bf16"]
    if precision == "auto" and bf16:
        names = [short(n) for a, n in result["algorithms"].items() if any(r["algorithm"] == a for r in bf16)]
        return f"bf16 at batch {_thousands(bf16[0]['batch_size'])} for {', '.join(names)} (`auto`)"
    label = f"{precision}, batch {_thousands(batch) if batch else 'auto'}"
    return label + (" (default)" if (precision, batch) == ("fp32", 256) else "")


def precision_table(results: list[Result]) -> str:
    """The best deep learner of benchmarks that differ in their updates' precision and batch, a column each (the
    algorithms named on the blueprint), and the last one's gain on the blueprint over the first."""
    lines = _head(["dataset", *map(precision_label, results), "gain"])
    for beh in _behaviours(results):
        first, last = best_mean(results[0], beh, "blueprint"), best_mean(results[-1], beh, "blueprint")
        gain = "-" if first is None or last is None else _minus(f"{last - first:+.1f}")
        lines.append(_row([beh, *(best_cell(r, beh) for r in results), gain]))
    return "\n".join(lines) + "\n"


def scores_with_online(result: Result, variant: str) -> str:
    """:func:`~dtradar_rl.experiments.offline_report.score_table` of one twin, its first cell naming the scene, the
    twin and the online agent's normalised score there (when the benchmark evaluated one)."""
    lines = score_table(result, variant)
    online = ((result.get("online_dqn") or {}).get(variant) or {}).get("normalized")
    corner = f"{scene_of(result)} → {variant}" + ("" if online is None else f" (online agent: {_one(online)})")
    lines[0] = re.sub(r"^\| [^|]*\|", lambda _: f"| {corner} |", lines[0], count=1)
    return "\n".join(lines) + "\n"


__all__ = [
    "behaviour_cell",
    "best",
    "best_cell",
    "best_learners_table",
    "defaults_table",
    "logged_table",
    "ogbench_table",
    "precision_label",
    "precision_table",
    "relabelling_table",
    "run_label",
    "scene_title",
    "scores_with_online",
    "senses_table",
    "tabular_cell",
    "updates_table",
]
