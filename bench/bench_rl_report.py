"""The Markdown report of ``bench/bench_rl.py``: the heading, the throughput rows and the full table (the script
writes the JSON and calls these for ``results/bench_rl*.md``)."""

from __future__ import annotations

from dtradar_rl.evaluation.evaluate import markdown_table
from dtradar_rl.task.runtime import describe


def _header(r: dict) -> list[str]:
    d = r["dataset"]
    src = "synthetic 42x18 stand-in (no ray-traced table built yet)" if d["synthetic"] else f"real twin {d['name']}"
    load = r["machine"]["load_1min_before"]
    return [
        (
            f"## RL benchmark ({src}; {describe(r['machine'])}, torch {r['machine']['torch_threads']} threads, "
            f"1-min load before start {'n/a' if load is None else f'{load:.2f}'})"
        ),
        "",
        "| measure | ours | reference | ratio |",
        "|---|---|---|---|",
    ]


def _throughput_label(key: str) -> str:
    """``batched_4096`` -> ``batched 4096 robots``; ``batched_general_4096`` -> ``... (general path)``;
    ``batched_4096_t1`` -> ``... (1 torch thread)``."""
    parts = key.split("_")
    general = "general" in parts
    parts = [p for p in parts if p != "general"]
    label = f"batched {parts[1]} robots"
    if general:
        label += " (general path)"
    if len(parts) > 2:
        n = parts[2][1:]
        label += f" ({n} torch thread{'s' if n != '1' else ''})"
    return label


def _throughput_rows(thr: dict) -> list[str]:
    return [
        f"| env steps/s, {_throughput_label(k)} | {v:,.0f} | gymnasium env {thr['gymnasium']:,.0f} | "
        f"{v / thr['gymnasium']:.2g}x |"
        for k, v in thr.items()
        if k != "gymnasium"
    ]


def render_markdown(r: dict, throughput: bool = True) -> str:
    """The report; ``throughput=False`` leaves out the env's steps/s rows (a page that shows them in a table of their
    own, from ``--env-only``)."""
    t, sb3 = r["train"], r["sb3"]
    lines = _header(r) + (_throughput_rows(r["env_steps_per_s"]) if throughput else [])
    lines.append(
        f"| greedy decision latency | {r['decision_latency_ms']:.3f} ms | paper 17 ms | "
        f"{r['decision_speedup_vs_paper']:.0f}x faster |"
    )
    lines.append(
        f"| wall time, {t['env_steps']:,} env steps | {t['wall_s']:.1f} s | paper 46 min | "
        f"{t['speedup_vs_paper']:.0f}x faster |"
    )
    rob = r.get("train_robust")
    if rob:
        lines.append(
            f"| wall time, same budget, robust preset ({rob['config']['aug_obstacles']} extra obstacles "
            f"per episode) | {rob['wall_s']:.1f} s | tuned {t['wall_s']:.1f} s | "
            f"{rob['wall_s'] / t['wall_s']:.2f}x |"
        )
    for n, run in (r.get("sb3_by_threads") or {}).items():
        if "wall_s_for_budget" in run and len(r["sb3_by_threads"]) > 1:
            lines.append(
                f"| SB3 DQN at {n} torch thread(s), same budget | | {run['wall_s_for_budget']:.0f} s "
                f"({run['env_steps']:,} steps in {run['wall_s']:.0f} s) | |"
            )
    if "wall_s_for_budget" in sb3:
        cap = f" (capped at {sb3['env_steps']:,} steps; extrapolated)" if sb3["capped"] else ""
        if len(r.get("sb3_by_threads") or {}) > 1:
            cap += f", its fastest: {sb3['threads']} thread(s)"
        lines.append(
            f"| wall time, same budget | {t['wall_s']:.1f} s | "
            f"SB3 DQN {sb3['wall_s_for_budget']:.0f} s{cap} | {t['speedup_vs_sb3']:.1f}x faster |"
        )
        dft = r.get("train_default")
        if dft and "speedup_vs_sb3" in dft:
            lines.append(
                f"| wall time, same budget, default preset ({dft['config']['preset']}, {dft['updates']:,} updates) | "
                f"{dft['wall_s']:.1f} s | SB3 DQN {sb3['wall_s_for_budget']:.0f} s | "
                f"{dft['speedup_vs_sb3']:.1f}x faster |"
            )
    lines += [
        "",
        (
            f"Goal (budget in <= 60 s, >= 95 % success, SPL >= 0.9 on blueprint -> blueprint): "
            f"**{'met' if t['goal_met'] else 'not met'}**."
        ),
        "",
        markdown_table(r["eval"]),
    ]
    return "\n".join(lines)


def _thousands(n: int) -> str:
    """``289821`` -> ``289 821`` (the docs' thousands separator)."""
    return f"{n:,}".replace(",", " ")


def _rate(v: float) -> str:
    """Steps/s to three significant digits with K or M: ``17.4 K``, ``2.83 M``."""
    x = float(f"{v:.3g}")
    scale, unit = (1e6, "M") if x >= 1e6 else (1e3, "K") if x >= 1e3 else (1.0, "")
    return f"{x / scale:g} {unit}".rstrip()


def env_table(r: dict) -> str:
    """``--env-only``'s throughput as one table: a row per batched env size, its fast path (the default), its general
    path, its fast path at the other thread counts measured, and the gymnasium env (one robot's row); the fastest in
    bold."""
    thr = r["env_steps_per_s"]
    counts = sorted({int(k.split("_")[-1]) for k in thr if k.startswith("batched_") and "_t" not in k})
    threads = sorted({int(k.rsplit("_t", 1)[1]) for k in thr if "_t" in k})
    general = any(k.startswith("batched_general_") for k in thr)
    best = max(thr.values())
    head = ["robots", "fast path (default)"] + (["general path"] if general else [])
    head += [f"fast path, {n} thread{'s' if n != 1 else ''}" for n in threads] + ["gymnasium env"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---:|" * len(head)]
    for k in counts:
        keys = [f"batched_{k}"] + ([f"batched_general_{k}"] if general else []) + [f"batched_{k}_t{n}" for n in threads]
        cells = [_thousands(k)] + [
            "" if key not in thr else f"**{_rate(thr[key])}**" if thr[key] == best else _rate(thr[key]) for key in keys
        ]
        cells.append(_rate(thr["gymnasium"]) if k == counts[0] else "")
        lines.append("|" + "|".join(f" {c} " if c else " " for c in cells) + "|")
    return "\n".join(lines) + "\n"


def _budget(steps: int) -> str:
    return f"{steps / 1e6:g} M" if steps >= 1e6 else f"{steps / 1e3:g} K"


def _pair(row: dict | None) -> str:
    return "" if row is None else f"{row['success_rate']:.3f} / {row['spl']:.3f}"


def sb3_table(r: dict) -> str:
    """Ours against SB3 at the same budget: a row per preset trained (``tuned``, and the default preset with its
    updates), its wall time, SB3's for the budget, the ratio, and each one's success / SPL on the blueprint and the
    dynamic twin; SB3's own row last."""
    sb3, name = r["sb3"], r["dataset"]["name"]
    scene = name.split("/")[0]

    def ours(label: str, twin: str) -> dict | None:
        return next((e for e in r["eval"] if e["case"] == f"ours ({label}): {name} -> {scene}/{twin}"), None)

    cap = (
        f" (capped at {r['config']['sb3_max_seconds']:.0f} s: {_thousands(sb3['env_steps'])} steps, extrapolated)"
        if sb3["capped"]
        else ""
    )
    lines = [
        f"| {_budget(r['config']['budget'])} env steps | wall time | SB3 DQN{cap} | ratio | success / SPL blueprint | "
        "success / SPL dynamic |",
        "|---|---:|---:|---:|---|---|",
    ]
    runs = [("tuned", "`tuned`", r["train"])]
    dft = r.get("train_default")
    if dft:
        preset = dft["config"]["preset"]
        runs.append((f"default, {preset}", f"`{preset}` ({_thousands(dft['updates'])} updates)", dft))
    for label, shown, t in runs:
        lines.append(
            f"| {shown} | {t['wall_s']:.1f} s | {sb3['wall_s_for_budget']:.0f} s | "
            f"**{sb3['wall_s_for_budget'] / t['wall_s']:.1f}×** | {_pair(ours(label, 'blueprint'))} | "
            f"{_pair(ours(label, 'dynamic'))} |"
        )
    lines.append(f"| SB3 DQN | | | | {_pair(sb3.get('blueprint'))} | {_pair(sb3.get('dynamic'))} |")
    return "\n".join(lines) + "\n"
