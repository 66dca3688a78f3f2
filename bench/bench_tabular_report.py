"""The Markdown report and the figure of ``bench/bench_tabular.py`` (the script writes the JSON and calls these for
``results/bench_tabular*.{md,png}``), and the tables of docs/results/tabular.md in the page's form, from that JSON
alone (``make results-pages``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dtradar_rl.task.runtime import describe
from dtradar_rl.viz.plots import _save, plt

#: The tabular learners (a table each), by their keys in the JSON; the others are DQN presets.
TABULAR = ("qlearning", "dyna")


def markdown(result: dict[str, Any]) -> str:
    a = result["args"]
    lines = [
        f"## Tabular learners beside the DQN at equal env steps ({a['steps']:,} steps, seed {a['seed']}, "
        f"{a['pairs']} seeded pairs, pair seed {a['eval_seed']}; {describe(result['machine']['start'])})",
        "",
        f"`{result['command']}`. Curves: greedy success / SPL on the blueprint's pairs at each checkpoint. Training "
        "seconds exclude the evaluations; every training single-threaded, one after the other.",
    ]
    for scene, s in result["scenes"].items():
        learners = s["learners"]
        amb = s["ambiguity"]
        lines += [
            "",
            f"### {scene} ({s['datasets']['blueprint']}, {s['datasets']['dynamic']})",
            "",
            "Fingerprints: "
            + "; ".join(
                f"{twin}: {v['free_cells']} free cells, {v['shared']} share a fingerprint exactly, {v['no_radio']} "
                f"without radio features, {v['mislocalised']} localised elsewhere (mean error "
                f"{v['mean_error_cells']:.1f} cells)"
                for twin, v in amb.items()
            )
            + ".",
            "",
            "| env steps | " + " | ".join(learners[k]["label"] for k in learners) + " |",
            "|---:|" + "---|" * len(learners),
        ]
        steps = sorted({r["env_steps"] for v in learners.values() for r in v["curve"]})
        by_step = {k: {r["env_steps"]: r for r in v["curve"]} for k, v in learners.items()}
        for st in steps:
            cells = []
            for k in learners:
                r = by_step[k].get(st)
                cells.append(f"{r['success']:.3f} / {r['spl']:.3f}" if r else "")
            lines.append(f"| {st:,} | " + " | ".join(cells) + " |")
        lines += [
            "",
            "| learner | training (s) | blueprint: success / SPL | dynamic: success / SPL / collisions | dynamic, "
            "true cell (oracle): success / SPL / collisions | "
            + " | ".join(f"steps to {lv}" for lv in a["reach"])
            + " | DQN steps / its steps (to "
            + str(a["reach"][0])
            + ") | DQN s / its s |",
            "|---|---:|---|---|---|" + "---:|" * len(a["reach"]) + "---:|---:|",
        ]
        dqn = learners.get("dqn")
        for k, v in learners.items():
            f = v["final"]
            mode = "fingerprint" if k in TABULAR else "-"
            bp, dy = f[f"blueprint/{mode}"], f[f"dynamic/{mode}"]
            orc = f.get("dynamic/oracle")
            reach = [v["reach"][str(lv)] for lv in a["reach"]]
            d_reach = dqn["reach"][str(a["reach"][0])] if dqn else None
            ratio = f"{d_reach / reach[0]:.1f}x" if d_reach and reach[0] else "-"
            t_ratio = f"{dqn['train_s'] / v['train_s']:.1f}x" if dqn and v["train_s"] > 0 else "-"
            lines.append(
                f"| {v['label']} | {v['train_s']:.1f} | {bp['success']:.3f} / {bp['spl']:.3f} | "
                f"{dy['success']:.3f} / {dy['spl']:.3f} / {dy['collisions']:.2f} | "
                + (f"{orc['success']:.3f} / {orc['spl']:.3f} / {orc['collisions']:.2f}" if orc else "-")
                + " | "
                + " | ".join(f"{r:,}" if r else "never" for r in reach)
                + f" | {ratio} | {t_ratio} |"
            )
    return "\n".join(lines) + "\n"


def plot(result: dict[str, Any], path: Path) -> Path:
    scenes = list(result["scenes"])
    fig, axes = plt.subplots(len(scenes), 2, figsize=(10, 3.4 * len(scenes)), squeeze=False)
    for i, scene in enumerate(scenes):
        for j, (key, name) in enumerate((("success", "success rate"), ("spl", "SPL"))):
            ax = axes[i, j]
            for k, v in enumerate(result["scenes"][scene]["learners"].values()):
                xs = [r["env_steps"] for r in v["curve"]]
                ax.plot(xs, [r[key] for r in v["curve"]], marker="o", ms=3, color=f"C{k}", label=v["label"])
            ax.set_xscale("log")
            ax.set_ylim(0, 1.02)
            ax.set_xlabel("environment steps")
            ax.set_title(f"{scene}: {name} on the blueprint", fontsize=9)
            ax.grid(alpha=0.3)
            if (i, j) == (0, 0):
                ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def sweep_markdown(result: dict[str, Any]) -> str:
    a = result["args"]
    lines = [
        f"## Settings of the tabular learners ({a['sweep_scene']}/blueprint, seeds {' '.join(map(str, a['seeds']))}, "
        f"{a['pairs']} pairs of seed {a['sweep_pair_seed']}; {describe(result['machine']['start'])})",
        "",
        f"`{result['command']}`. One setting changed at a time from the defaults; mean ± sd over the seeds.",
        "",
        "| learner | env steps | setting | success | SPL | training (s) |",
        "|---|---:|---|---|---|---:|",
    ]
    for r in result["rows"]:
        setting = (
            r["setting"] if isinstance(r["setting"], str) else ", ".join(f"{k}={v}" for k, v in r["setting"].items())
        )
        lines.append(
            f"| {r['learner']} | {r['steps']:,} | {setting} | {r['success']:.3f} ± {r['success_sd']:.3f} | "
            f"{r['spl']:.3f} | {r['train_s']:.1f} |"
        )
    return "\n".join(lines) + "\n"


# -- the results page's tables (docs/results/tabular.md) -------------------------------------------------------------
def _twin(scene: str) -> str:
    """``Dallas Q3`` for a city quadrant, else the scene's name."""
    city, _, q = scene.rpartition("-q")
    return f"{city.capitalize()} Q{q}" if city and q.isdigit() else scene


def _learner(v: dict[str, Any]) -> str:
    """``Dyna-Q``; a DQN by its preset: ``DQN `tuned```."""
    label = v["label"]
    return f"DQN `{label[5:-1]}`" if label.startswith("DQN (") else label


def page_curves(result: dict[str, Any], at: list[int]) -> str:
    """Every scene's learning curves side by side, a column per (scene, learner), a row at the first checkpoint at
    or after each of ``at`` (the env steps the page shows): greedy success / SPL on the blueprint's pairs."""
    head, columns = ["env steps"], []
    for scene, s in result["scenes"].items():
        for i, v in enumerate(s["learners"].values()):
            head.append((f"{_twin(scene)}: " if i == 0 else "") + _learner(v))
            columns.append({r["env_steps"]: r for r in v["curve"]})
    steps = sorted({st for c in columns for st in c})
    lines = ["| " + " | ".join(head) + " |", "|---:|" + "---|" * len(columns)]
    for want in at:
        st = next((x for x in steps if x >= want), None)
        if st is None:
            continue
        cells = [f"{c[st]['success']:.3f} / {c[st]['spl']:.3f}" if st in c else "" for c in columns]
        lines.append(f"| {st:,} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _collisions(x: float) -> str:
    return f"{x:.2f}" if x < 10 else f"{x:.1f}"


def page_learners(result: dict[str, Any]) -> str:
    """A row per (scene, learner): training seconds, the env steps its curve first reached each ``--reach`` success
    (thousands), and the final policy on the dynamic twin, localising by fingerprint and (a table) with the true
    cell."""
    levels = result["args"]["reach"]
    lines = [
        "| twin | learner | training (s) | env steps to "
        + " / ".join(f"{lv:g}" for lv in levels)
        + " success | dynamic: success / SPL / collisions | dynamic, true cell: success / SPL |",
        "|---|---|---:|---|---|---|",
    ]
    for scene, s in result["scenes"].items():
        for k, v in s["learners"].items():
            f = v["final"]
            dy = f["dynamic/fingerprint" if k in TABULAR else "dynamic/-"]
            orc = f.get("dynamic/oracle")
            reach = [v["reach"][str(lv)] for lv in levels]
            lines.append(
                f"| {_twin(scene)} | {v['label']} | {v['train_s']:.1f} | "
                + " / ".join(f"{round(r / 1000)} K" if r else "never" for r in reach)
                + f" | {dy['success']:.3f} / {dy['spl']:.3f} / {_collisions(dy['collisions'])} | "
                + (f"{orc['success']:.3f} / {orc['spl']:.3f}" if orc else "-")
                + " |"
            )
    return "\n".join(lines) + "\n"
