"""Renderers of docs/results/paper.md: the tables of ``make paper``'s report.json (its own page forms,
dtradar_rl.experiments.paper_tables), the cross-quadrant matrix of ``python -m dtradar_rl cross`` (cross.json), and
the city navigation table, assembled here from each quadrant's ``eval`` results.json and the idle training times of a
``make paper`` report (no single command writes that table)."""

from __future__ import annotations

from typing import Any

from renderers.base import Renderer, module


def _tables(func: str):
    return module("dtradar_rl.experiments.paper_tables", func)


def _own_rows(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The evaluated checkpoint's own rows of an ``eval`` results.json: unshielded, neither the planner's nor the
    privileged DQN's (which ``eval`` of a default agent adds beside it)."""
    return [
        r
        for r in result["results"]
        if not r.get("shield") and not r["case"].startswith(("planner: ", "privileged DQN: "))
    ]


def navigation_table(data: list[dict[str, Any]], options: dict[str, str]) -> str:
    """A row per quadrant's blueprint, then its other twins (a dynamic one), from each quadrant's ``eval``
    results.json (all but the last JSON): success, SPL, collisions, mean steps / mean shortest, and the training time
    its checkpoint records beside the one a ``make paper`` report (the last JSON) records for the same preset on an
    idle machine."""
    title = _tables("title")
    *evals, report = data
    idle = {s: v for c in report.get("cross", []) for s, v in c["train_s"].items()}
    first, later = [], []
    for result in evals:
        scene = result["config"]["eval"]["scene"]
        shared = result["config"].get("train_stats", {}).get("wall_s")
        for r in _own_rows(result):
            variant = r["dataset"].split("/")[1]
            cells = [f"{r['success_rate']:.3f}", f"{r['spl']:.3f}", f"{r['collisions']:.2f}",
                     f"{r['steps']:.1f} / {r['shortest']:.1f}"]  # fmt: skip
            if variant == "blueprint":
                times = " / ".join("-" if t is None else f"{t:.0f} s" for t in (shared, idle.get(scene)))
                first.append([title(scene), *cells, times])
            else:
                later.append([f"{title(scene)} → {variant}", *cells, ""])
    head = ["quadrant", "success", "SPL", "collisions/ep", "mean steps / mean shortest",
            "training time: shared CPU / idle"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|---|---:|---:|---:|---|---:|"]
    return "\n".join(lines + [("| " + " | ".join(r)).rstrip() + " |" for r in first + later]) + "\n"


_PAPER = 'make paper SCENES=<scenes> ARGS="--out {dir}" (with the seeds and options the page names; writes {json})'

#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "paper-seeds": Renderer(lambda d, o: _tables("seeds_table")(d), _PAPER),
    "paper-per-seed": Renderer(lambda d, o: _tables("per_seed_table")(d), _PAPER),
    "paper-one-seed": Renderer(lambda d, o: _tables("one_seed_table")(d), _PAPER),
    "paper-until": Renderer(
        lambda d, o: _tables("until_table")(d),
        "python -m dtradar_rl paper --scenes <scenes> --seeds <seeds> --no-cross --max-steps 600000 "
        "--total-env-steps 600000 --out {dir} (one report per run the page names; a scene's seeds are merged)",
        several=True,
    ),
    "paper-cross": Renderer(
        lambda d, o: _tables("matrix_table")(d["config"]["matrix"]),
        "python -m dtradar_rl cross --scenes <scenes> --checkpoint-pattern <pattern> --pairs 500 --out {dir}",
    ),
    "paper-navigation": Renderer(
        navigation_table,
        'make eval SCENE=<quadrant> ARGS="--checkpoint <its model.pt> --out {dir}" per quadrant, then the make paper '
        "report of the same quadrants, its JSON last (the page names each)",
        several=True,
    ),
}
