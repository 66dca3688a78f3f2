"""Renderers of docs/results/ray-tracing.md: the tables one benchmark's JSON makes call its own renderer (the
differential re-trace, the radio map); the tables assembled from several runs (two solvers or path buffers of
bench_rt.py, two builds of bench_moving.py, the dataset cards of a city build) are laid out here from the fields those
runs' JSON hold."""

from __future__ import annotations

from renderers.base import Renderer, bench

SUPERSCRIPT = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")


def count(n: int) -> str:
    """An integer with a space per thousand: 1 894."""
    return f"{n:,}".replace(",", " ")


def power(n: int) -> str:
    """10⁴ for 10000, 3·10⁴ for 30000; other numbers with a space per thousand."""
    digits = str(n)
    e = len(digits) - 1
    if n > 0 and digits[1:] == "0" * e and e > 0:
        exp = str(e).translate(SUPERSCRIPT)
        return f"10{exp}" if digits[0] == "1" else f"{digits[0]}·10{exp}"
    return count(n)


def pct(x: float) -> str:
    return f"{100 * x:.1f} %"


# ------------------------------------------------------------------------------------- bench_rt.py, several runs
def solvers(runs: list[dict], twins: list[str], beside: set[int]) -> str:
    """Both solvers side by side: the runs in pairs (batch-independent, then ``--stock-solver``), one pair per twin,
    labelled ``twins``. A row per samples_per_src of the batch-independent run; the scene's default (what a build
    traces with) is named, and its batch-independent agreement in bold; the cells/s of a run in ``beside`` (1-based:
    measured beside other jobs) in parentheses."""
    if len(runs) != 2 * len(twins):
        raise ValueError(f"{len(runs)} runs for {len(twins)} twins: give a batch-independent and a stock run each")
    lines = [
        "| twin, samples | batch-independent: agreement / paths found / median gain error / cells/s | Sionna's solver: "
        "the same |",
        "|---|---|---|",
    ]
    for i, twin in enumerate(twins):
        own, stock = runs[2 * i], runs[2 * i + 1]
        by_samples = {r["samples_per_src"]: r for r in stock["rows"]}
        default = own["default_samples_per_src"]
        kind = "city" if "samples_per_src" in own.get("scene_rt_defaults", {}) else "indoor"
        for r in own["rows"]:
            s = r["samples_per_src"]
            label = f"{twin}, {power(s)}" + (f" (the {kind} default)" if s == default else "")
            mine = _solver_cell(r, 2 * i + 1 in beside, bold=s == default)
            theirs = _solver_cell(by_samples[s], 2 * i + 2 in beside) if s in by_samples else "–"
            lines.append(f"| {label} | {mine} | {theirs} |")
    return "\n".join(lines) + "\n"


def _solver_cell(r: dict, beside: bool, bold: bool = False) -> str:
    agreement = f"**{pct(r['agreement'])}**" if bold else pct(r["agreement"])
    speed = f"({r['cells_per_s']})" if beside else f"{r['cells_per_s']}"
    return f"{agreement} / {100 * r['paths_found_vs_reference']:.0f} % / {r['median_abs_gain_error_db']} dB / {speed}"


def buffers(runs: list[dict]) -> str:
    """Runs that differ in their rows' path buffer (``--buffer``), their rows one after the other."""
    lines = [
        "| samples_per_src | path buffer | cells/s | strongest-path agreement | cells with a path | paths found | "
        "median abs. gain error |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    lines += [
        f"| {r['samples_per_src']:,} | {power(run['path_buffer'])} | {r['cells_per_s']} | {pct(r['agreement'])} | "
        f"{pct(r['found_path_share'])} | {100 * r['paths_found_vs_reference']:.0f} % | "
        f"{r['median_abs_gain_error_db']:.2f} dB |"
        for run in runs
        for r in run["rows"]
    ]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------- bench_moving.py, several builds
def moving(runs: list[dict]) -> str:
    """Builds of one moving twin side by side, a column each, named by how many helper processes traced beside the
    build (``taskset -c 0`` leaves none); the fastest warm build in bold; a cell equal to the one left of it says so."""
    first = runs[0]
    n = first["snapshots"]
    best = min(_warm(r) for r in runs)
    head = [f"{first['scene']}, {n} snapshots", *(_helpers(r["helpers"]) for r in runs)]
    rows = [
        ("build, warm (first compile apart)", [_build(r, len(runs) > 1 and _warm(r) == best) for r in runs]),
        (
            f"snapshots 1–{n - 1}: differential vs full",
            [
                f"{r['differential_total_s']:.1f} s vs {r['full_total_s']:.1f} s: {r['speedup_total']:.2f}×"
                for r in runs
            ],
        ),
        ("agreement with the full trace; seed floor", [_agreement(r) for r in runs]),
    ]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * len(runs)]
    for label, cells in rows:
        shown = [c if i == 0 or c != cells[i - 1] else "the same" for i, c in enumerate(cells)]
        lines.append(f"| {label} | " + " | ".join(shown) + " |")
    return "\n".join(lines) + "\n"


def _helpers(n: int) -> str:
    return "one process" if n == 0 else "with a helper" if n == 1 else f"with {n} helpers"


def _warm(r: dict) -> float:
    return r["goals"]["build_time"]["warm_s"]


def _build(r: dict, bold: bool) -> str:
    text = f"{_warm(r):.1f} s"
    return f"{f'**{text}**' if bold else text} (+ {r['first_compile_s']:.1f} s)"


def _agreement(r: dict) -> str:
    agree = (
        "100 % in every snapshot"
        if r["agreement_min"] >= 1
        else f"{pct(r['agreement_mean'])} on average, lowest {pct(r['agreement_min'])}"
    )
    floors = [f["agreement"] for f in r["seed_floor"]]
    return f"{agree}; {pct(min(floors)) if floors else 'no seed floor'}"


# ------------------------------------------------------------------------- dataset cards (python -m dtradar_data cards)
def build_times(cards: list[dict]) -> str:
    """A row per dataset card (``card.json``: the stored version's meta and its build's statistics)."""
    lines = ["| dataset | free cells | cells with a path | paths | trace time |", "|---|---:|---:|---:|---:|"]
    for card in cards:
        meta, stats = card["meta"], card["meta"]["stats"]
        share = f"{100 * stats['num_with_paths'] / stats['num_free']:.1f}".removesuffix(".0")
        lines.append(
            f"| `{meta['name']}` | {count(stats['num_free'])} | {count(stats['num_with_paths'])} ({share} %) | "
            f"{count(stats['num_paths_total'])} | {stats['trace_seconds']:.0f} s |"
        )
    return "\n".join(lines) + "\n"


def _indices(text: str) -> set[int]:
    return {int(x) for x in text.split(";") if x.strip()}


#: name -> renderer.
RENDERERS: dict[str, Renderer] = {
    "ray-tracing-solvers": Renderer(
        lambda d, o: solvers(d, o["twins"].split(";"), _indices(o["beside"])),
        "python bench/bench_rt.py (once per twin without and with --stock-solver, with the options the page names; "
        "writes {dir}/bench_rt[_<scene>][_buffer<N>][_stock].json)",
        options=("twins", "beside"),
        several=True,
    ),
    "ray-tracing-buffers": Renderer(
        lambda d, o: buffers(d),
        "python bench/bench_rt.py --out {dir} (once per --buffer, with the options the page names; writes "
        "{dir}/bench_rt_<scene>[_buffer<N>][_stock].json)",
        several=True,
    ),
    "ray-tracing-differential": Renderer(
        lambda d, o: bench("bench_differential.py", "markdown")(d, d[0]["machine"]),
        'make bench-diff SCENES="<scenes>" ARGS="--out {dir}" (writes {dir}/bench_differential_<scene>.json)',
        several=True,
    ),
    "ray-tracing-moving": Renderer(
        lambda d, o: moving(d),
        'make bench-moving SCENES=<scene> ARGS="--out <folder>" (a folder per build, in the table\'s order; '
        "taskset -c 0 for one process; writes <folder>/bench_moving_<scene>.json)",
        several=True,
    ),
    "ray-tracing-radiomap": Renderer(
        lambda d, o: bench("bench_radiomap_report.py", "summary")(d),
        'make bench-radiomap SCENE=cubicle ARGS="--out {dir}"',
    ),
    "ray-tracing-build-times": Renderer(
        lambda d, o: build_times(d),
        'make dataset SCENE=<city> (with the options the page names), then make cards ARGS="--out <folder> --names '
        '<datasets>" (writes <folder>/<scene>/<variant>/card.json)',
        several=True,
    ),
}
