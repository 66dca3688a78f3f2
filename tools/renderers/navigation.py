"""Renderers of the navigation page's tables (docs/results/navigation.md; navigation-movers.md's: navigation_moving.py).

A table of one benchmark's JSON calls that benchmark's own function (bench/bench_nav.py, bench_latency.py,
bench_dynamic.py); a table assembled from several runs of ``python -m dtradar_rl eval`` (one ``results.json`` per run:
its ``config`` names the scene, the evaluation's noise, the checkpoint's training config and seconds, the twins' free
cells; its ``results`` the rows) or from several benchmarks is laid out here, reading only those JSONs' fields."""

from __future__ import annotations

import numpy as np
from renderers.base import Renderer, bench

from dtradar_rl.train.config import DEFAULT_PRESET, budget_for

#: Rows of an ``eval`` results.json that are not of the checkpoint evaluated (eval adds them beside it).
OTHERS = ("planner: ", "privileged DQN: ")
#: How the page names a twin where it is not its scene's name.
TWIN_NAMES = {
    "dallas-q1": "Dallas Q1",
    "dallas-q2": "Dallas Q2",
    "dallas-q3": "Dallas Q3",
    "dallas-q4": "Dallas Q4",
    "sionna-munich-10tx": "Munich, ten transmitters",
}
#: The commands of the tables assembled from ``eval`` runs: each run's --out is the folder its JSON is in.
EVAL = (
    "python -m dtradar_rl eval --scene <twin> --checkpoint <run>/model.pt --out {dir} (one run per JSON of the marker)"
)


def thousands(n: float) -> str:
    """``1625`` -> ``1 625`` (the docs' thousands separator)."""
    return f"{n:,.0f}".replace(",", " ")


def budget(steps: int) -> str:
    """A training budget as the page writes it: ``600 K``, ``979 K`` (978 500), ``1.53 M``, ``2.4 M``."""
    return f"{steps / 1e6:.3g} M" if steps >= 1_000_000 else f"{int(steps / 1000 + 0.5)} K"


def scene(res: dict) -> str:
    return res["config"]["eval"]["scene"]


def own(res: dict, variant: str, shield: bool = False) -> dict | None:
    """The evaluated checkpoint's row on ``<scene>/<variant>`` (shielded or not), or None when not evaluated."""
    name = f"{scene(res)}/{variant}"
    return next(
        (
            r
            for r in res["results"]
            if r["dataset"] == name and bool(r.get("shield")) == shield and not r["case"].startswith(OTHERS)
        ),
        None,
    )


def pair(row: dict | None, collisions: str = "") -> str:
    """``success / SPL`` (with ``collisions`` a format: ``/ collisions``), ``-`` for a twin not evaluated."""
    if row is None:
        return "-"
    return f"{row['success_rate']:.3f} / {row['spl']:.3f}" + (
        f" / {collisions.format(row['collisions'])}" if collisions else ""
    )


def spread(values: list[float], fmt: str = "{:.3f}") -> str:
    """Mean ± standard deviation over seeds (the mean alone for one)."""
    v = np.asarray(values, float)
    return fmt.format(v.mean()) + (f" ± {fmt.format(v.std())}" if v.size > 1 else "")


# -- tables of eval runs ---------------------------------------------------------------------------------------------
def margin(results: list[dict], options: dict[str, str]) -> str:
    """With and without the margin loss: a row per run (its twin and free cells, preset, budget, blueprint and dynamic
    success / SPL / collisions, training seconds); the default preset at its twin's own budget in bold."""
    lines = [
        "| twin (free cells) | agent | budget | blueprint: success / SPL / collisions | dynamic: success / SPL / "
        "collisions | training (s) |",
        "|---|---|---:|---|---|---:|",
    ]
    for res in results:
        free = res["config"]["free_cells"][f"{scene(res)}/blueprint"]
        train = res["config"]["train"]
        steps, preset = train["total_env_steps"], train["preset"]
        mark = "**" if preset == DEFAULT_PRESET and steps == budget_for(free) else ""
        dyn = own(res, "dynamic")
        cells = [
            f"{TWIN_NAMES.get(scene(res), scene(res))} ({thousands(free)})",
            f"{mark}`{preset}`{mark}",
            budget(steps),
            f"{mark}{pair(own(res, 'blueprint'), '{:.2f}')}{mark}",
            "-" if dyn is None else f"{mark}{pair(dyn, '{:.2f}')}{mark}",
            thousands(res["config"]["train_stats"]["wall_s"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def noise_trained(results: list[dict], options: dict[str, str]) -> str:
    """Trained on exact or on noisy features: a row per (twin, noise at evaluation), the first preset's blueprint and
    dynamic success / SPL, then the second preset's (``blueprint · dynamic``); the runs in the table's order."""
    rows: dict[tuple[str, str], dict[str, dict]] = {}
    for res in results:
        key = (scene(res), res["config"]["eval"]["noise"])
        rows.setdefault(key, {})[res["config"]["train"]["preset"]] = res
    presets = list(dict.fromkeys(p for runs in rows.values() for p in runs))
    first, second = presets
    lines = [
        f"| twin | noise at evaluation | `{first}`: blueprint success / SPL | dynamic: success / SPL | `{second}`: "
        "blueprint · dynamic |",
        "|---|---|---|---|---|",
    ]
    for (twin, noise), runs in rows.items():
        a, b = runs[first], runs[second]
        other = pair(own(b, "blueprint")) + ("" if own(b, "dynamic") is None else f" · {pair(own(b, 'dynamic'))}")
        lines.append(f"| {twin} | {noise} | {pair(own(a, 'blueprint'))} | {pair(own(a, 'dynamic'))} | {other} |")
    return "\n".join(lines) + "\n"


def unseen(results: list[dict], options: dict[str, str]) -> str:
    """Unseen obstacles: a row per run (scene, preset, training seconds), blueprint, dynamic (collisions with one
    decimal) and dynamic with the shield."""
    lines = [
        "| scene | agent | train time | blueprint → blueprint: success / SPL | → dynamic: success / SPL / collisions | "
        "→ dynamic, shielded: success / SPL |",
        "|---|---|---:|---|---|---|",
    ]
    for res in results:
        lines.append(
            f"| {scene(res)} | {res['config']['train']['preset']} | {res['config']['train_stats']['wall_s']:.1f} s | "
            f"{pair(own(res, 'blueprint'))} | {pair(own(res, 'dynamic'), '{:.1f}')} | "
            f"{pair(own(res, 'dynamic', shield=True))} |"
        )
    return "\n".join(lines) + "\n"


def noise_levels(results: list[dict], options: dict[str, str]) -> str:
    """One agent under each noise level: a row per run (its ``--noise``), blueprint, dynamic and dynamic shielded."""
    lines = [
        "| noise | blueprint: success / SPL | dynamic: success / SPL / collisions | dynamic, shielded |",
        "|---|---|---|---|",
    ]
    for res in results:
        lines.append(
            f"| {res['config']['eval']['noise']} | {pair(own(res, 'blueprint'))} | "
            f"{pair(own(res, 'dynamic'), '{:.2f}')} | {pair(own(res, 'dynamic', shield=True))} |"
        )
    return "\n".join(lines) + "\n"


# -- the zero-shot table: bench_dynamic's runs beside make bench-rl's ------------------------------------------------
def _bench_rl_rows(rl: dict, twin: str) -> list[str]:
    """The robust agent's and SB3's rows of a ``make bench-rl`` run on ``twin`` (collisions with one decimal, no
    decision time)."""
    command = "make bench-rl" if twin == "cubicle" else f'make bench-rl ARGS="--scene {twin}"'

    def case(prefix: str, variant: str) -> dict:
        return next(
            e for e in rl["eval"] if e["case"].startswith(prefix) and e["case"].endswith(f"-> {twin}/{variant}")
        )

    out = []
    for prefix, label in (
        ("ours (robust", f"robust (seed {(rl.get('train_robust') or {}).get('config', {}).get('seed', 0)})"),
        ("SB3 DQN: ", f"SB3 DQN (seed 0, `{command}`)"),  # bench_rl's SB3 run has seed 0
    ):
        if any(e["case"].startswith(prefix) for e in rl["eval"]):
            bp, dy = case(prefix, "blueprint"), case(prefix, "dynamic")
            out.append(f"| {twin} | {label} | {pair(bp)} | {pair(dy)} | {dy['collisions']:.1f} | – |")
    return out


def _bench_dynamic_rows(run: dict, twin: str, agents: list[str]) -> list[str]:
    """``agents``' rows of a ``bench_dynamic.py`` run on ``twin``: mean ± spread over its seeds, the median decision
    time on the dynamic twin; the learnt agents (not the planner) in bold, with the budget where it is not 600 K."""
    out = []
    for agent in agents:
        sel = {
            t: [r for r in run["rows"] if (r["scene"], r["agent"], r["twin"]) == (twin, agent, t)]
            for t in ("blueprint", "dynamic")
        }
        if not sel["dynamic"]:
            continue

        def cell(t: str, sel=sel) -> str:
            return f"{spread([r['success_rate'] for r in sel[t]])} / {spread([r['spl'] for r in sel[t]])}"

        steps = run["args"]["steps"]
        label, mark = ("planner (classical)", "") if agent == "planner" else (agent, "**")
        label += "" if agent == "planner" or steps == 600_000 else f", {budget(steps)} steps"
        out.append(
            f"| {twin} | {mark}{label}{mark} | {cell('blueprint')} | {mark}{cell('dynamic')}{mark} | "
            f"{spread([r['collisions'] for r in sel['dynamic']], '{:.2f}')} | "
            f"{np.median([r['latency_ms'] for r in sel['dynamic']]):.2f} |"
        )
    return out


def zero_shot(results: list[dict], options: dict[str, str]) -> str:
    """Zero-shot on the dynamic twins: per scene (in the runs' order) the planner (of the first ``bench_dynamic.py``
    run), the robust agent and SB3 (``make bench-rl``'s run of the scene), then the learnt agents of every
    ``bench_dynamic.py`` run of the scene."""
    dyn = [r for r in results if "adapt" in r]
    rl = {r["dataset"]["name"].split("/")[0]: r for r in results if "train" in r and "eval" in r}
    twins: list[str] = []
    for r in results:
        twins += list(r["args"]["scenes"]) if "adapt" in r else [r["dataset"]["name"].split("/")[0]]
    lines = [
        "| scene | agent | blueprint → blueprint: success / SPL | → dynamic: success / SPL | collisions/ep (dynamic) "
        "| decision (ms) |",
        "|---|---|---|---|---|---|",
    ]
    for twin in dict.fromkeys(twins):
        runs = [r for r in dyn if twin in r["args"]["scenes"]]
        lines += _bench_dynamic_rows(runs[0], twin, ["planner"]) if runs else []
        lines += _bench_rl_rows(rl[twin], twin) if twin in rl else []
        for run in runs:
            lines += _bench_dynamic_rows(run, twin, list(run["args"]["presets"]))
    return "\n".join(lines) + "\n"


#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "navigation-sb3": Renderer(
        lambda d, o: bench("bench_nav.py", "agent_table")(d),
        'make bench-nav SCENES="<the twins>" ARGS="--out {dir} --name {name}" (SB3\'s rows without noise)',
    ),
    "navigation-latency": Renderer(
        lambda d, o: bench("bench_latency.py", "markdown_twins")(d),
        'make bench-latency SCENE=<twin> ARGS="--out {dir}" for each twin (writes {dir}/bench_latency_<twin>.json)',
        several=True,
    ),
    "navigation-adapt": Renderer(
        lambda d, o: bench("bench_dynamic.py", "adapt_table")(d),
        "python bench/bench_dynamic.py --presets memory --out {dir} --name {name}",
    ),
    "navigation-zero-shot": Renderer(
        zero_shot,
        "python bench/bench_dynamic.py --presets memory --scenes <scene> --name bench_dynamic_<scene>, and make "
        "bench-rl (--scene <scene>) (the marker names each run's JSON)",
        several=True,
    ),
    "navigation-margin": Renderer(margin, EVAL, several=True),
    "navigation-noise-trained": Renderer(noise_trained, EVAL, several=True),
    "navigation-unseen": Renderer(unseen, EVAL, several=True),
    "navigation-noise-levels": Renderer(noise_levels, EVAL, several=True),
}
