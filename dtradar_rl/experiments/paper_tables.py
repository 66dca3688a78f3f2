"""The results page's tables of ``make paper`` (docs/results/paper.md), from ``report.json`` alone.

``report.md`` (:mod:`.paper_report`) lays every column out for one run; the page quotes a few in its own form and
sets several runs side by side (the Dallas quadrants' seeds came from three reports). Each function here reads the
JSON of :class:`~dtradar_rl.experiments.paper.Report` (``json.loads`` of ``report.json``), never the run folders, so
``make results-pages`` regenerates the page from the reports a re-run writes.
"""

from __future__ import annotations

import re
import statistics
from typing import Any

from dtradar_rl.experiments.paper_report import _spread
from dtradar_rl.experiments.paper_seeds import WITHIN, needed

_QUADRANT = re.compile(r"^(.+)-q(\d)$")


def title(scene: str) -> str:
    """``Dallas Q3`` for a city quadrant, else the scene's name."""
    m = _QUADRANT.match(scene)
    return f"{m.group(1).capitalize()} Q{m.group(2)}" if m else scene


def num(v: float | int) -> str:
    """``6 843``, ``280.5``: thousands by a space, a decimal only where the value has one."""
    if float(v).is_integer():
        return f"{int(v):,}".replace(",", " ")
    return f"{v:,.1f}".replace(",", " ")


def _table(head: list[str], rows: list[list[Any]], align: list[str] | None = None) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "".join(f"{a}|" for a in (align or ["---"] * len(head)))]
    return "\n".join(lines + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]) + "\n"


def _paper(t: dict[str, Any]) -> str:
    p = t.get("paper")
    return f"{num(p['min_steps'])} ({p['episode']})" if p else "-"


def _cell(pair) -> str:
    return f"{tuple(pair['start'])} → {tuple(pair['target'])}"


def _within(r: dict[str, Any]) -> bool:
    return r["min_steps"] is not None and r["min_steps"] <= WITHIN * r["pair"]["shortest"]


# -- the paper's agent over seeds (one report) -------------------------------------------------------------------
def seeds_table(report: dict[str, Any]) -> str:
    """Table VI judged over seeds, a row per scene: the pair, how many seeds reproduce it, the greedy policies, and
    the spread of the training minima."""
    rows = []
    for t in report["training"]:
        g, n = t["greedy_reached"], t["n_seeds"]
        rows.append(
            [
                t["scene"],
                _cell(t["pair"]),
                t["pair"]["shortest"],
                f"**{t['reproduced']} of {n}**",
                f"{g.get('blueprint', 0)} of {n} / " + (f"{g['dynamic']} of {n}" if "dynamic" in g else "-"),
                _spread(t["min_steps"]),
                _spread(t["min_episode"]),
                _spread(t["first_within_10pct"]),
                _paper(t),
            ]
        )
    head = ["scene", "pair (ours)", "shortest path", "seeds reproducing the pair", "greedy reaches: blueprint / "
            "dynamic", "min steps: median [range]", "its episode: median [range]", "first episode within 10 %: "
            "median [range]", "paper: min steps (episode)"]  # fmt: skip
    return _table(head, rows, ["---", "---", "---:", *["---"] * 6])


def _reached(g: dict[str, Any] | None) -> str:
    return "-" if g is None else ("reached" if g["reached"] else "not reached")


def _seed_cell(r: dict[str, Any]) -> str:
    """``42 at 79; reached / reached; 39 049``: the training minimum at its episode, the greedy policy on the
    blueprint / dynamic twin (in bold, with its collisions, where it misses the blueprint's target), env steps."""
    best = "never reached" if r["min_steps"] is None else f"{r['min_steps']} at {r['min_episode']}"
    bp, dyn = r["greedy"].get("blueprint"), r["greedy"].get("dynamic")
    greedy = f"{_reached(bp)} / {_reached(dyn)}"
    if bp is not None and not bp["reached"]:
        greedy = f"**{greedy}** ({bp['collisions']} collisions)"
    return f"{best}; {greedy}; {num(r['env_steps'])}"


def per_seed_table(report: dict[str, Any]) -> str:
    """A row per seed, a column per scene: each run in one cell (:func:`_seed_cell`)."""
    scenes = [t["scene"] for t in report["training"]]
    by = {t["scene"]: {r["seed"]: r for r in t["runs"]} for t in report["training"]}
    seeds = sorted({s for runs in by.values() for s in runs})
    rows = [[s, *(_seed_cell(by[sc][s]) if s in by[sc] else "-" for sc in scenes)] for s in seeds]
    return _table(["seed", *scenes], rows, ["---:", *["---"] * len(scenes)])


def _both(g: dict[str, Any]) -> str:
    """The greedy outcome on the blueprint, and on the dynamic twin where there is one."""
    bp, dyn = _reached(g["blueprint"]), _reached(g.get("dynamic"))
    if "dynamic" not in g:
        return bp
    return f"{bp} (blueprint and dynamic)" if bp == dyn else f"{bp} (blueprint), {dyn} (dynamic)"


def one_seed_table(report: dict[str, Any]) -> str:
    """A row per scene from its first seed's run: the training minimum, the greedy policy after training, the env
    steps and the training time."""
    rows, episodes = [], set()
    for t in report["training"]:
        r = t["runs"][0]
        episodes.add(r["episodes"])
        best = "never reached" if r["min_steps"] is None else f"{r['min_steps']} ({r['min_episode']})"
        rows.append(
            [title(t["scene"]), t["pair"]["shortest"], best, _both(r["greedy"]), num(r["env_steps"]),
             f"{r['wall_s']:.0f} s", _paper(t)]
        )  # fmt: skip
    steps = f"env steps, {episodes.pop()} episodes" if len(episodes) == 1 else "env steps"
    head = ["quadrant", "shortest path", "min steps of a training episode that reached the target (episode)",
            "greedy after training", steps, "training time", "paper: min steps (episode)"]  # fmt: skip
    return _table(head, rows, ["---", "---:", "---", "---", "---:", "---:", "---"])


# -- episodes until the target, seeds from several reports -----------------------------------------------------------
def merged(reports: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each scene's training entry with the runs of every report, by seed (a scene's seeds may come from several
    runs of ``make paper``), in the order the scenes first appear."""
    out: dict[str, dict[str, Any]] = {}
    for rep in reports:
        for t in rep["training"]:
            e = out.setdefault(t["scene"], {**t, "runs": []})
            e["runs"] = sorted(e["runs"] + t["runs"], key=lambda r: r["seed"])
    return list(out.values())


def _range(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{num(statistics.median(values))} [{num(lo)}" + ("" if lo == hi else f"-{num(hi)}") + "]"


def _trained(runs: list[dict[str, Any]]) -> str:
    """``5 of 5``, and where an episode never ended: after how many finished ones (``seed 2's first never ended``
    where none did)."""
    said = f"{sum(r['reached'] > 0 for r in runs)} of {len(runs)}"
    after = [str(r["episodes"]) for r in runs if r.get("unfinished_steps") and r["episodes"]]
    never = [str(r["seed"]) for r in runs if r.get("unfinished_steps") and not r["episodes"]]
    notes = []
    if after:
        listed = after[0] if len(after) == 1 else ", ".join(after[:-1]) + " and " + after[-1]
        notes.append(f"{listed} episodes, then one that never ended")
    if never:
        notes.append(f"seed{'s' if len(never) > 1 else ''} {' and '.join(never)}'s first never ended")
    return said + (f" ({'; '.join(notes)})" if notes else "")


def _near(runs: list[dict[str, Any]]) -> str:
    """``**k of n**`` seeds whose training found a path within 10 % of the optimum; below the goal, their minima
    (or, where none did, every seed's, ``-`` for a seed that never reached the target)."""
    k = sum(_within(r) for r in runs)
    said = f"**{k} of {len(runs)}**"
    if k >= needed(len(runs)):
        return said
    listed = [r["min_steps"] for r in runs if _within(r)] if k else [r["min_steps"] for r in runs]
    return said + " (" + ", ".join("-" if v is None else str(v) for v in listed) + ")"


def _misses(runs: list[dict[str, Any]], variant: str) -> str:
    return ", ".join(str(r["greedy"][variant]["closest"]) for r in runs if not r["greedy"][variant]["reached"])


def until_table(reports: list[dict[str, Any]]) -> str:
    """The paper's protocol (episodes until the target) over seeds, a row per quadrant, its seeds merged from
    ``reports`` (:func:`merged`)."""
    rows = []
    for t in merged(reports):
        runs = t["runs"]
        n, dyn = len(runs), all("dynamic" in r["greedy"] for r in runs)
        best = [r["min_steps"] for r in runs if r["min_steps"] is not None]
        at = [r["min_episode"] for r in runs if r["min_episode"] is not None]
        greedy = f"{sum(r['greedy']['blueprint']['reached'] for r in runs)} of {n}"
        misses = _misses(runs, "blueprint") or "-"
        if dyn:
            greedy += f" (dynamic: {sum(r['greedy']['dynamic']['reached'] for r in runs)} of {n})"
            misses += f" (dynamic {_misses(runs, 'dynamic') or '-'})"
        first = [r["first_episode_steps"] for r in runs]
        rows.append(
            [
                title(t["scene"]),
                t["pair"]["shortest"],
                _trained(runs),
                _near(runs),
                f"{_range(best)} ({_range(at)})" if best else "never reached",
                greedy,
                misses,
                _range(first)[:-1] + (", unfinished]" if not all(r["first_episode_finished"] for r in runs) else "]"),
                _paper(t),
            ]
        )
    head = ["quadrant", "shortest", "seeds whose training reaches the target (every episode does)", "a training path "
            "within 10 % of the optimum", "min steps: median [range] (its episode)", "greedy reaches it afterwards",
            "greedy misses: nearest approach (cells)", "the first episode: median [range] steps",
            "paper: min steps (episode)"]  # fmt: skip
    return _table(head, rows, ["---", "---:", *["---"] * 7])


# -- cross-quadrant inference ------------------------------------------------------------------------------------
def matrix_table(m: dict[str, Any]) -> str:
    """The train-on-row x evaluate-on-column matrix (``cross_matrix``'s dict: in ``cross.json``'s config and in each
    ``report.json`` cross entry), success / SPL, the own quadrant in bold; a city's quadrants named Q1..Q4."""

    def name(s: str) -> str:
        q = _QUADRANT.match(s)
        return f"Q{q.group(2)}" if q and len({_QUADRANT.sub(r"\1", x) for x in m["rows"] + m["cols"]}) == 1 else s

    rows = []
    for i, r in enumerate(m["rows"]):
        cells = []
        for j, c in enumerate(m["cols"]):
            v = f"{m['success'][i][j]:.3f} / {m['spl'][i][j]:.3f}"
            cells.append(f"**{v}**" if r == c else v)
        rows.append([name(r), *cells])
    return _table(["trained on \\ evaluated on", *map(name, m["cols"])], rows)


__all__ = ["matrix_table", "merged", "num", "one_seed_table", "per_seed_table", "seeds_table", "title", "until_table"]
