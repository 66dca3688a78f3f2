"""The report of ``bench/bench_radiomap.py``: the Markdown of a result (a summary, the two tables of
docs/results/ray-tracing.md, then every row by hypothesis) and the figure. It reads nothing but the JSON, so
``make results-pages`` re-renders the page's tables from ``results/bench_radiomap/bench_radiomap.json`` alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np

SUPERSCRIPT = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")


def markdown(result: dict) -> str:
    """The report: a heading with the machine and command, the summary, then one table per hypothesis."""
    lines = [
        f"# PathSolver against RadioMapSolver: {result['scene']} ({result['free_cells']} free cells, "
        f"{result['machine']})",
        "",
        f"`{result['command']}`: PathSolver {result['ps_samples']:.0e} samples (batch-independent unless said), "
        f"radio map {result['rm_samples']:.0e} samples, {result['rm_cell_m']} m cells at z = {result['plane_z_m']} m "
        f"(receivers at {result['rx_height_m']} m), max_depth {result['max_depth']}; PathSolver minus radio map in dB "
        "over the free cells; total time {:.0f} s.".format(result["seconds"]),
        "",
        "## Summary",
        "",
        summary(result).rstrip("\n"),
    ]
    head = "| compared | cells | median | median abs. | p90 abs. | ratio of means | table red., median | paths "
    head += "| PathSolver s | radio map s |"
    for group in ("antennas", "area", "interactions", "samples"):
        lines += ["", f"## {group}", "", head, "|---|" + "---:|" * 9]
        for r in (r for r in result["rows"] if r["group"] == group):
            table = f"{r['table_median_db']:+.2f} dB" if "table_median_db" in r else ""
            lines.append(
                f"| {r['what']} | {r['cells']} | {r['median_db']:+.2f} dB | {r['median_abs_db']:.2f} dB | "
                f"{r['p90_abs_db']:.2f} dB | {r['mean_linear_ratio_db']:+.2f} dB | {table} | {r.get('paths', '')} | "
                f"{r['ps_s'] or ''} | {r['rm_s'] or ''} |"
            )
    return "\n".join(lines) + "\n"


def summary(result: dict) -> str:
    """The page's two tables: the ablations, one change at a time (PathSolver minus radio map over the free cells),
    and the interactions, the same on both sides. Rows are found by the labels the benchmark gave them."""
    return "\n".join([*_ablations(result), "", *_interactions(result)]) + "\n"


def _signed(x: float) -> str:
    """dB with its sign and a true minus (a rounded 0 unsigned, a rounded negative -0 as −0.00)."""
    s = f"{x:+.2f}"
    return ("0.00" if s == "+0.00" else s).replace("-", "−")


def _count(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def _power(n: int) -> str:
    """10⁷ for 10000000 (other numbers with a space per thousand)."""
    e = len(str(n)) - 1
    return "10" + str(e).translate(SUPERSCRIPT) if n == 10**e else _count(n)


def _row(result: dict, group: str, what: str) -> dict:
    """The benchmark's row ``what`` of ``group`` (KeyError: the JSON is of another benchmark or version)."""
    for r in result["rows"]:
        if r["group"] == group and r["what"] == what:
            return r
    raise KeyError(f"no {group} row {what!r}")


def _cells(*rows: dict, sep: str = " / ") -> str:
    """Median, median abs., p90 abs. and ratio of means of one row, or of several joined by ``sep``."""
    keys = (("median_db", _signed), ("median_abs_db", "{:.2f}".format), ("p90_abs_db", "{:.2f}".format))
    keys += (("mean_linear_ratio_db", _signed),)
    return " | ".join(sep.join(f(r[k]) for r in rows) + " dB" for k, f in keys)


def _ablations(result: dict) -> list[str]:
    scene, k, cell = result["scene"].split("/")[0], result["subpoints"], result["rm_cell_m"]
    every = result["solo_every"]

    def get(group: str, what: str) -> dict:
        return _row(result, group, what)

    precoded = get("antennas", "precoded vs radio map (default precoding)")
    lines = [
        f"| ablation ({scene}, PathSolver minus radio map over the free cells) | median | median abs. | p90 abs. "
        "| ratio of means |",
        "|---|---:|---:|---:|---:|",
    ]
    rows = [
        (
            "table's reduction (V port, port mean), the offset",
            get("antennas", "table vs radio map (default precoding)"),
        ),
        (
            "step 1, PathSolver both sides: V port against both ports",
            get("antennas", "  step 1: table vs full-pol ports (PathSolver both)"),
        ),
        (
            f"step 2, PathSolver both sides: port mean against the `1/√{result['tx_ports']}` beam",
            get("antennas", "  step 2: full-pol ports vs precoded (PathSolver both)"),
        ),
        ("both ports, port mean (step 1 removed)", get("antennas", "full-pol ports vs radio map (default precoding)")),
        ("both ports, precoded as the radio map (steps 1 and 2 removed)", precoded),
        (
            "both ports, port mean, against a port-averaged radio map (one-hot precodings)",
            get("antennas", "full-pol ports vs port-averaged radio map"),
        ),
        ("datasets' dipole, table's reduction", get("antennas", "dataset's dipole V, port mean vs radio map")),
        (f"area: precoded, mean of {k}×{k} points per cell", get("area", f"mean of {k}x{k} points vs {cell:g} m cell")),
    ]
    sub = get("area", f"each point vs its {cell / k:g} m sub-cell")
    rows.append((f"area: each point against its {cell / k:g} m radio-map sub-cell ({_count(sub['cells'])})", sub))
    lines += [f"| {label} | {_cells(r)} |" for label, r in rows]
    los = (
        get("area", f"LoS only: centre point vs {cell:g} m cell"),
        get("area", f"LoS only: mean of {k}x{k} points vs {cell:g} m cell"),
    )
    lines.append(f"| area, LoS only: centre point → mean of {k}×{k} points | {_cells(*los, sep=' → ')} |")
    for n in result["rm_sweep"]:
        r = get("samples", f"radio map {n:.0e} samples")
        lines.append(
            f"| samples: radio map {_power(n)} instead of {_power(result['rm_samples'])} (precoded) | {_cells(r)} |"
        )
    for n in result["ps_sweep"]:
        r = get("samples", f"PathSolver {n:.0e} samples")
        lines.append(
            f"| samples: PathSolver {_power(n)} instead of {_power(result['ps_samples'])} ({_count(r['paths'])} "
            f"paths, not {_count(precoded['paths'])}; precoded) | {_cells(r)} |"
        )
    one = get("samples", f"Sionna's own PathSolver, {result['free_cells']} receivers in one call")
    solo = get("samples", f"Sionna's own PathSolver, one receiver per call (every {every}th cell)")
    same = (get("samples", "  the same cells in one call"), get("samples", "  the same cells, batch-independent"))
    return lines + [
        f"| Sionna's own PathSolver, {result['free_cells']} receivers in one call ({_count(one['paths'])} paths; "
        f"precoded) | {_cells(one)} |",
        f"| Sionna's own PathSolver, one receiver per call (every {every}th cell, {solo['cells']}; precoded) | "
        f"{_cells(solo)} |",
        f"| the same {solo['cells']} cells: in the one call / batch-independent | {_cells(*same)} |",
    ]


def _interactions(result: dict) -> list[str]:
    depth = result["max_depth"]

    def get(what: str) -> dict:
        return _row(result, "interactions", what)

    def line(label: str, *rows: dict) -> str:
        """One setting, or several joined by " / " (their median abs. as the range it spans)."""
        low, high = (f"{f(r['median_abs_db'] for r in rows):.2f}" for f in (min, max))
        cells = [
            " / ".join(_count(r["paths"]) for r in rows),
            " / ".join(_signed(r["median_db"]) for r in rows) + " dB",
            (low if low == high else f"{low}–{high}") + " dB",
            " / ".join(f"{r['p90_abs_db']:.2f}" for r in rows) + " dB",
            " / ".join(_signed(r["table_median_db"]) for r in rows) + " dB",
        ]
        return f"| {label} | " + " | ".join(cells) + " |"

    depths = result["depths"]
    lines = [
        "| interactions, the same on both sides | paths | precoded: median | median abs. | p90 abs. | table's "
        "reduction: median |",
        "|---|---:|---:|---:|---:|---:|",
        line("LoS only", get("LoS only")),
        line(
            f"LoS + specular, depth {' / '.join(map(str, depths))}",
            *(get(f"LoS + specular, depth {d}") for d in depths),
        ),
        line(f"LoS + refraction, depth {depth}", get(f"LoS + refraction, depth {depth}")),
        line(
            f"LoS + specular + refraction, depth {depth} (the datasets)",
            get(f"LoS + specular + refraction, depth {depth} (datasets)"),
        ),
    ]
    if result["diffraction"]:
        lines.append(line(f"+ diffraction, depth {depth}", get(f"+ diffraction, depth {depth}")))
    return lines


def plot(cells: dict, path: Path, title: str) -> None:
    """Histogram of the per-cell differences for each reduction, and PathSolver against radio map per cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rm = 10 * np.log10(cells["rm"])
    series = [(f"{n} (iso receiver)", 10 * np.log10(v)) for n, v in cells["red"].items()]
    series.append(("table, dataset's dipole", 10 * np.log10(cells["dipole"])))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    bins = np.linspace(-20, 20, 81)
    for name, db in series:
        d = db - rm
        ax1.hist(
            d[np.isfinite(d)], bins=bins, histtype="step", lw=1.5, label=f"{name}: median {np.nanmedian(d):+.2f} dB"
        )
        ax2.plot(rm, db, ".", ms=3, label=name)
    ax1.axvline(0, color="k", lw=0.8)
    ax1.set_xlabel("PathSolver minus radio map per free cell [dB]")
    ax1.set_ylabel("cells")
    ax1.legend(fontsize=8, loc="upper left")
    lo, hi = np.nanmin(rm), np.nanmax(rm)
    ax2.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax2.set_xlabel("radio map (default precoding) [dB]")
    ax2.set_ylabel("PathSolver [dB]")
    ax2.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
