"""The report of ``bench/bench_moving.py``: the figure and the Markdown of one scene's result (the script writes
them, with the JSON, to ``results/bench_moving_<scene>.{png,md,json}``)."""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def plot(res: dict, path: Path) -> None:
    rows = res["per_snapshot"]
    ks = np.array([r["k"] for r in rows])
    diff_s = np.array([r["differential_s"] for r in rows])
    full_s = np.array([r["full_s"] for r in rows])
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    colours = ["#9ecae1" if r["mode"] == "differential" else "#404040" for r in rows]
    ax.bar(ks, diff_s, color=colours, label="built: differential from k-1 (dark: snapshot 0, full)")
    ax.plot(ks, full_s, "o-", color="#d62728", ms=3, lw=1, label="full trace of the same instant")
    ax.set_ylabel("seconds per snapshot")
    ax.set_ylim(0, max(full_s.max(), diff_s.max()) * 1.15)
    frac = ax.twinx()
    frac.plot(ks[1:], [r["retraced_cells"] / r["free_cells"] for r in rows[1:]], ":", color="0.4", lw=1)
    frac.set_ylim(0, 1.05)
    frac.set_ylabel("fraction of free cells re-traced (dotted)")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(
        f"{res['scene']}/moving, {res['snapshots']} snapshots: differential {res['differential_total_s']:.0f} s vs "
        f"full {res['full_total_s']:.0f} s for t >= 1 ({res['speedup_total']:.2f}x); build "
        f"{res['goals']['build_time']['warm_s']:.0f} s warm",
        fontsize=9,
    )
    d = [r for r in rows if r["mode"] == "differential"]
    kd = [r["k"] for r in d]
    for key, style, label in (
        ("all", "o-", "all free cells"),
        ("retraced", "^--", "re-traced cells"),
        ("kept", "v--", "kept cells"),
    ):
        vals = [100 * r["differential_vs_full"][key]["agreement"] for r in d]
        bx.plot(kd, vals, style, ms=3 if key == "all" else 2, lw=1.2 if key == "all" else 0.7, label=label)
    static = [100 * r["snapshot0_vs_full"]["agreement"] for r in d]
    bx.plot(kd, static, ":", color="0.4", lw=1, label="snapshot 0 reused")
    for i, f in enumerate(res["seed_floor"]):
        bx.axhline(
            100 * f["agreement"],
            color="k",
            ls="-.",
            lw=0.8,
            label="seed floor (two full traces, seed +1)" if i == 0 else None,
        )
    bx.set_ylabel("agreement with the full trace [%]")
    bx.set_xlabel("snapshot k")
    bx.legend(loc="lower left", fontsize=8, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)


def markdown(res: dict) -> str:
    """The Markdown of one scene's result: the setting, the timings, the goals, the per-snapshot table."""
    return (
        "\n".join(
            [
                f"# `{res['scene']}/moving`: differential snapshots vs full traces",
                "",
                _setting(res),
                "",
                *_timings(res),
                "",
                *_goals(res["goals"]),
                "",
                *_snapshot_table(res["per_snapshot"]),
                *_repeats(res),
                "",
                "Snapshot 0 of the build is a full trace and the reference of t = 0; the seed floor compares a full "
                "trace with seed + 1 to the one with the build's seed at the same instant.",
            ]
        )
        + "\n"
    )


def _pct(x) -> str:
    """A fraction as a percentage with one decimal."""
    return f"{100 * x:.1f} %"


def _verdict(goal) -> str:
    """A goal's outcome in bold; a goal the run could not judge (``met`` is None) says so."""
    return "not evaluated" if goal["met"] is None else ("**met**" if goal["met"] else "**not met**")


def _setting(res: dict) -> str:
    """The paragraph of what was run: snapshots against the twin's own horizon, movers, grid, tracer settings and
    the machine."""
    rt = res["rt"]
    return (
        f"{res['snapshots']} snapshots of {res['dt_s']:g} s (the twin's own horizon: {res['own_horizon']}; "
        + (
            "past it the movers go round again, each snapshot still traced from the one before"
            if res["snapshots"] > res["own_horizon"]
            else "cut short"
            if res["snapshots"] < res["own_horizon"]
            else "all of it"
        )
        + f"), {res['movers']} movers, {res['grid'][0]} × {res['grid'][1]} cells, re-trace radius "
        f"{res['radius_m']:g} m, max_depth {rt.get('max_depth')}, {rt.get('samples_per_src'):g} samples, batches of "
        f"{rt.get('batch_size')}, seed {rt.get('seed')}"
        + ("" if rt.get("batch_independent", False) else ", `--rt.no-batch-independent`")
        + f". Machine: {res['machine']} at the start, "
        f"{res['machine_after']} at the end."
    )


def _timings(res: dict) -> list[str]:
    """The bullets of the compile, the build, differential against full, and agreement with the seed floor."""
    g = res["goals"]
    floors = ", ".join(f"{_pct(f['agreement'])} (t = {f['k']})" for f in res["seed_floor"]) or "not run"
    return [
        f"- First JIT compile (excluded from every time below): {res['first_compile_s']:.1f} s.",
        f"- Build (`moving.trace_snapshots` + `moving_tables`, warm): {g['build_time']['warm_s']:.1f} s for "
        f"{res['snapshots']} snapshots ({res['build_tables_s']:.1f} s of it joining the table); "
        f"{g['build_time']['with_first_compile_s']:.1f} s with the compile.",
        f"- Snapshots 1–{res['snapshots'] - 1}: differential {res['differential_total_s']:.1f} s in all vs full "
        f"{res['full_total_s']:.1f} s ({res['speedup_total']:.2f}× in total, median {res['speedup_median']:.2f}× per "
        f"snapshot, worst {g['speedup']['min']:.2f}×); {_pct(res['retraced_fraction_mean'])} of the free cells "
        "re-traced on average.",
        f"- Agreement with the full trace of the same instant (strongest path, free cells): mean "
        f"{_pct(res['agreement_mean'])}, lowest {_pct(res['agreement_min'])}; seed-noise floor {floors}.",
    ]


def _goals(g: dict) -> list[str]:
    """The three goals (speed-up, agreement, build time), each with its verdict and the counts behind it."""
    return [
        "Goals:",
        "",
        f"- {g['speedup']['goal']}: {_verdict(g['speedup'])} ({g['speedup']['snapshots_meeting']} of "
        f"{g['speedup']['of']} snapshots; worst {g['speedup']['min']:.2f}×).",
        f"- {g['agreement']['goal']}: {_verdict(g['agreement'])} ({g['agreement']['snapshots_meeting']} of "
        f"{g['agreement']['of']} snapshots).",
        f"- {g['build_time']['goal']}: {_verdict(g['build_time'])} ({g['build_time']['warm_s']:.1f} s warm for "
        f"{g['build_time']['snapshots']} snapshots).",
    ]


def _snapshot_table(per_snapshot: list[dict]) -> list[str]:
    """One row a snapshot; a full trace (snapshot 0) is the reference, so it has no ratio or agreement."""
    lines = [
        "| k | re-traced | differential s | full s | ratio | agreement all / re-traced / kept | median / p95 "
        "abs. gain diff | snapshot 0 reused | previous full reused |",
        "|---:|---:|---:|---:|---:|---|---:|---:|---:|",
    ]
    for r in per_snapshot:
        if r["mode"] == "full":
            lines.append(
                f"| {r['k']} | {r['retraced_cells']} of {r['free_cells']} (full) | {r['differential_s']:.2f} | "
                f"{r['full_s']:.2f} | – | (the reference) | – | – | – |"
            )
            continue
        a = r["differential_vs_full"]
        kept = _pct(a["kept"]["agreement"]) if a["kept"]["cells"] else "–"
        redo = _pct(a["retraced"]["agreement"]) if a["retraced"]["cells"] else "–"
        lines.append(
            f"| {r['k']} | {r['retraced_cells']} of {r['free_cells']} | {r['differential_s']:.2f} | "
            f"{r['full_s']:.2f} | {r['speedup']:.2f}× | {_pct(a['all']['agreement'])} / {redo} / {kept} | "
            f"{a['all']['gain_median_db']:.3f} / {a['all']['gain_p95_db']:.2f} dB | "
            f"{_pct(r['snapshot0_vs_full']['agreement'])} | {_pct(r['previous_full_vs_full']['agreement'])} |"
        )
    return lines


def _repeats(res: dict) -> list[str]:
    """Past the twin's own horizon the movers repeat: how far the full traces agree with those a period before
    (none when the run stayed within the horizon)."""
    repeats = [r for r in res["per_snapshot"] if "full_vs_full_periods_before" in r]
    if not repeats:
        return []
    same = [r["full_vs_full_periods_before"]["agreement"] for r in repeats]
    return [
        "",
        f"Snapshots {repeats[0]['k']}–{repeats[-1]['k']} show the movers where snapshot k mod "
        f"{res['own_horizon']} (the twin's own horizon) does: their full traces agree with those in "
        f"{_pct(min(same))}–{_pct(max(same))} of the cells (same scene, same seed).",
    ]
