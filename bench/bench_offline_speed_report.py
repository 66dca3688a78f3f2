"""The report of ``bench/bench_offline_speed.py``: the Markdown tables and the figure of its result (the script
writes them, with the JSON, to ``results/bench_offline_speed.{md,png,json}``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dtradar_rl.task.runtime import describe


def markdown(result: dict[str, Any]) -> str:
    m = result["machine"]
    lines = [
        f"# d3rlpy training speed on `{result['logged']}` (medians over interleaved rounds)",
        "",
        f"Machine: {describe(m)}. d3rlpy {result['versions']['d3rlpy']}, torch {result['versions']['torch']}. "
        "Ratios are to the section's baseline within the same run; absolute numbers move with the other jobs on the "
        "machine (each section's load average at its start is given).",
        "",
        "| section | command | updates per measurement | rounds | load average at start | wall s |",
        "|---|---|---|---|---|---|",
    ]
    for name, sec in result["sections"].items():
        la = "/".join(f"{x:.1f}" for x in sec.get("load_average") or [])
        lines.append(
            f"| {name} | `{sec.get('command', '')}` | {sec.get('updates', '-')} | {sec.get('rounds', '-')} | {la} | "
            f"{sec.get('wall_s', 0):.0f} |"
        )
    lines.append("")
    s = result["sections"]
    if "algorithms" in s:
        lines += [
            "## Per algorithm",
            "",
            "| algorithm | variant | updates/s | ratio | sampling ms | update ms | same weights |",
            "|---|---|---|---|---|---|---|",
        ]
        for algo, rows in s["algorithms"]["per_algorithm"].items():
            for r in rows:
                lines.append(
                    f"| {algo} | {r['variant']} | {r['updates_per_s']:.1f} ({r['min']:.0f}-{r['max']:.0f}) | "
                    f"{r['ratio']:.2f} | {_ms(r['sample_ms'])} | {_ms(r['update_ms'])} | "
                    f"{_yes(r['same_weights'])} |"
                )
        lines.append("")
    if "threads" in s:
        lines += [
            "## Torch threads and the weights",
            "",
            "| algorithm | updates | 1 thread: updates/s | 2 threads: updates/s | same weights 1 vs 2 threads | "
            "same weights 2 vs 2 threads |",
            "|---|---|---|---|---|---|",
        ]
        for r in s["threads"]["rows"]:
            lines.append(
                f"| {r['algorithm']} | {r['updates']} | {r['updates_per_s_1']:.1f} | {r['updates_per_s_2']:.1f} | "
                f"{_yes(r['same_weights_1_vs_2'])} | {_yes(r['same_weights_2_vs_2'])} |"
            )
        lines.append("")
    for key, title in (("epochs", "Epochs (cql, 1 thread)"), ("evaluators", "Evaluators (cql, 1 thread)")):
        if key in s:
            lines += [f"## {title}", "", "| variant | updates/s | ratio | same weights |", "|---|---|---|---|"]
            for r in s[key]["rows"]:
                lines.append(
                    f"| {r['variant']} | {r['updates_per_s']:.1f} ({r['min']:.0f}-{r['max']:.0f}) | {r['ratio']:.2f} | "
                    f"{'yes' if r['same_weights'] else 'no'} |"
                )
            lines.append("")
    if "parallel" in s:
        p = s["parallel"]
        lines += [
            f"## Parallel trainings ({len(p['jobs'])} jobs x {p['updates']} updates: {', '.join(p['jobs'])})",
            "",
            "| layout | wall s (start-up included) | updates/s, all jobs | speed-up | updates/s of one training | "
            "same weights |",
            "|---|---|---|---|---|---|",
        ]
        for r in p["rows"]:
            lines.append(
                f"| {r['layout']} | {r['wall_s']:.1f} | {r['updates_per_s']:.1f} | {r['speedup']:.2f} | "
                f"{r['job_updates_per_s']:.1f} | {_yes(r['same_weights'])} |"
            )
        lines.append("")
    if "overhead" in s:
        o = s["overhead"]
        lines += ["## Fixed costs", "", f"- one `train_offline` run beside its updates: {o['fixed_s']:.1f} s (median)"]
        if "fqe" in o:
            lines.append(f"- FQE: {o['fqe']['updates_per_s']:.1f} updates/s ({o['fqe']['updates']} updates)")
        lines.append("")
    return "\n".join(lines)


def plot(result: dict[str, Any], path: Path) -> Path | None:
    """Updates per second of every variant of the algorithms section, one group of bars per algorithm (the ratio to
    the trainer's former loop written on each bar), and the parallel layouts beside them."""
    s = result["sections"]
    per = (s.get("algorithms") or {}).get("per_algorithm") or {}
    par = (s.get("parallel") or {}).get("rows") or []
    if not per and not par:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        1,
        2 if par else 1,
        figsize=(12 if par else 8, 4.2),
        squeeze=False,
        gridspec_kw={"width_ratios": [3, 1]} if par else None,
    )
    ax = axes[0][0]
    algos = list(per)
    variants = list(dict.fromkeys(r["variant"] for rows in per.values() for r in rows))
    width = 0.8 / max(1, len(variants))
    for k, v in enumerate(variants):
        xs, ys, ratios = [], [], []
        for i, a in enumerate(algos):
            r = next((r for r in per[a] if r["variant"] == v), None)
            if r is not None:
                xs.append(i + (k - (len(variants) - 1) / 2) * width)
                ys.append(r["updates_per_s"])
                ratios.append(r["ratio"])
        bars = ax.bar(xs, ys, width, label=v)
        for b, q in zip(bars, ratios):
            ax.annotate(
                f"{q:.2f}x", (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom", fontsize=6
            )
    ax.set_xticks(range(len(algos)), algos)
    ax.set_ylabel("d3rlpy updates per second")
    ax.set_title(f"training speed on {result['logged']}", fontsize=10)
    ax.legend(fontsize=7)
    if par:
        ax2 = axes[0][1]
        ax2.bar([r["layout"] for r in par], [r["updates_per_s"] for r in par], color=["C0", "C1"][: len(par)])
        for i, r in enumerate(par):
            ax2.annotate(f"{r['speedup']:.2f}x", (i, r["updates_per_s"]), ha="center", va="bottom", fontsize=8)
        ax2.set_ylabel("updates per second, all jobs")
        ax2.set_title("parallel trainings", fontsize=10)
        ax2.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _yes(x: bool | None) -> str:
    return "-" if x is None else ("yes" if x else "no")


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"
