"""Renderers of the tables of docs/results/navigation-movers.md (navigation among movers): runs of
``python -m dtradar_rl eval --variants moving``, one ``results.json`` each, laid out from their fields.

The rows' labels are the page's own words, given by the marker (``labels="a|b|..."``, one per row, in order); the
numbers come from the runs. The marker's JSONs are taken in order: a label opens the next run for its row, except a
label naming ``shielded``, which is the shielded row of the run before it (the same evaluation's), and a label
starting ``planner`` reads the planner's row (``eval`` without ``--no-planner``) of its run. A run of several
training seeds is several JSONs in a row whose ``--out`` folders differ only by a last ``-s<seed>``: its row shows
the mean (± the standard deviation over the seeds, where ``spread`` is yes) with two decimals for the mover counts.
Where ``bold`` is yes, each twin's fewest mover collisions are in bold."""

from __future__ import annotations

import re

import numpy as np
from renderers.base import Renderer
from renderers.navigation import OTHERS, budget, thousands

#: The commands of these tables (the marker names each run's folder, ``--out``).
MOVERS = (
    "python -m dtradar_rl train --scene <twin> --variant moving <flags> --out <run>, then python -m dtradar_rl eval "
    "--scene <twin> --variants moving --checkpoint <run>/model.pt --out {dir} (one run per JSON of the marker)"
)
SEEDS = re.compile(r"-s\d+$")


def _runs(results: list[dict]) -> list[list[dict]]:
    """The JSONs grouped into runs: consecutive ones whose ``--out`` differs only by a last ``-s<seed>``."""
    runs: list[list[dict]] = []
    last = None  # the run folder of the group before, where it is of seeds
    for res in results:
        out = str(res["config"]["eval"]["out"]).rstrip("/")
        key = SEEDS.sub("", out) if SEEDS.search(out) else None
        if key is not None and key == last:
            runs[-1].append(res)
        else:
            runs.append([res])
        last = key
    return runs


def _row(res: dict, kind: str) -> dict:
    """One evaluation's row on the moving twin: the checkpoint's (``agent``, or ``shielded``) or the planner's."""
    for r in res["results"]:
        if not r["dataset"].endswith("/moving"):
            continue
        if kind == "planner" and r["case"].startswith("planner: "):
            return r
        if kind != "planner" and not r["case"].startswith(OTHERS) and bool(r.get("shield")) == (kind == "shielded"):
            return r
    raise ValueError(f"no {kind} row on a moving twin in the run of {res['config']['eval']['out']}")


def rows(results: list[dict], labels: str) -> list[tuple[str, list[dict], list[dict]]]:
    """``(label, its rows (one per seed; the planner's: one), its run's JSONs)`` per label, in order."""
    runs, out, run = iter(_runs(results)), [], None
    for label in labels.split("|"):
        if "shielded" not in label or run is None:
            run = next(runs, None)
            if run is None:
                raise ValueError(f"labels name more runs than the marker's JSONs give (at {label!r})")
        kind = "shielded" if "shielded" in label else "planner" if label.startswith("planner") else "agent"
        out.append((label, [_row(res, kind) for res in run[: 1 if kind == "planner" else None]], run))
    if next(runs, None) is not None:
        raise ValueError("the marker names more runs than it has labels")
    return out


class _Cells:
    """The number cells of one row: success, SPL, mover collisions and hits."""

    def __init__(self, rs: list[dict], digits: int, spread: bool):
        self.rs, self.digits, self.spread = rs, digits, spread

    def value(self, key: str) -> float:
        return float(np.mean([r[key] for r in self.rs]))

    def cell(self, key: str, digits: int) -> str:
        v = np.asarray([r[key] for r in self.rs], float)
        if v.size > 1:
            return f"{v.mean():.{digits}f}" + (f" ± {v.std():.{digits}f}" if self.spread else "")
        return f"{v[0]:.{digits}f}"

    def shown(self) -> list[str]:
        movers = self.digits if len(self.rs) == 1 else 2
        return [self.cell("success_rate", 3), self.cell("spl", 3)] + [
            self.cell(k, movers) for k in ("mover_collisions", "mover_hits")
        ]

    def fewest(self) -> float:
        """The mover collisions as shown (ties shown alike are alike)."""
        return round(self.value("mover_collisions"), self.digits if len(self.rs) == 1 else 2)


def _table(results: list[dict], o: dict[str, str], head: list[str], align: str, extra) -> str:
    """The shared layout: ``twin | label | extra cells before | numbers | extra cells after``."""
    found = rows(results, o["labels"])
    cells = [_Cells(rs, int(o["digits"]), o.get("spread", "yes") == "yes") for _, rs, _ in found]
    twins = [rs[0]["dataset"] for _, rs, _ in found]
    best = {t: min(c.fewest() for c, u in zip(cells, twins, strict=True) if u == t) for t in set(twins)}
    lines = ["| " + " | ".join(head) + " |", align]
    for (label, rs, run), c, twin in zip(found, cells, twins, strict=True):
        shown = c.shown()
        if o.get("bold", "yes") == "yes" and c.fewest() == best[twin]:
            shown[2] = f"**{shown[2]}**"
        before, after = extra(rs, run)
        row = [twin, label, *before, *shown, *after]
        lines.append("|" + "|".join(f" {x} " if x else " " for x in row) + "|")
    return "\n".join(lines) + "\n"


def _seconds(rs: list[dict], run: list[dict]) -> float | None:
    """One run's training seconds (none for several seeds, or a run that did not record them)."""
    return run[0]["config"].get("train_stats", {}).get("wall_s") if len(run) == 1 else None


def trained(results: list[dict], o: dict[str, str]) -> str:
    """Trained among movers: a row per run, with its budget and training seconds."""
    head = [
        "twin",
        "agent (all with wait + clock + `--mover-penalty 4`, `--sense-radius 4`)",
        "budget",
        "success",
        "SPL",
        "mover collisions/ep",
        "mover hits/ep",
        "training (s)",
    ]

    def extra(rs, run):
        s = _seconds(rs, run)
        return [budget(run[0]["config"]["train"]["total_env_steps"])], ["" if s is None else thousands(s)]

    return _table(results, o, head, "|---|---|---:|---:|---:|---:|---:|---:|", extra)


def flags(results: list[dict], o: dict[str, str]) -> str:
    """The flags one at a time: a row per run, with its training seconds."""
    head = ["twin", "flags beyond `--sense-radius 4`", "success", "SPL", "mover collisions/ep", "mover hits/ep"]

    def extra(rs, run):
        s = _seconds(rs, run)
        return [], ["" if s is None else f"{s:.0f} s"]

    return _table(results, o, [*head, "training"], "|---|---|---:|---:|---:|---:|---:|", extra)


def agents(results: list[dict], o: dict[str, str]) -> str:
    """Agents among movers (and the planner): a row per label."""
    head = ["twin", "agent", "success", "SPL", "mover collisions/ep", "mover hits/ep"]
    return _table(results, o, head, "|---|---|---:|---:|---:|---:|", lambda rs, run: ([], []))


#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "navigation-movers-trained": Renderer(trained, MOVERS, ("labels", "digits"), ("spread", "bold"), several=True),
    "navigation-movers-flags": Renderer(flags, MOVERS, ("labels", "digits"), ("spread", "bold"), several=True),
    "navigation-movers": Renderer(agents, MOVERS, ("labels", "digits"), ("spread", "bold"), several=True),
}
