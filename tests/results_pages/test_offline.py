"""The tables of docs/results/offline.md and offline-first-benchmark.md: each renderer gives the committed page's
block back from JSONs in the shape their commands write (the offline benchmark's ``bench.json``, single ``offline``
runs' ``results.json``, ``bench/bench_relabel.py``'s ``bench.json``) holding the page's numbers, and a re-run's number
lands in it."""

import re

from dtradar_rl.experiments.offline_bench_config import NAMES
from dtradar_rl.offline.relabel import AUTO_MIXES

PAGE = "offline.md"
FIRST = "offline-first-benchmark.md"  # the first benchmark, before relabelling, and its budget
TWINS = ("blueprint", "dynamic")
KEY = {**{n: a for a, n in NAMES.items()}, **{n.removeprefix("Discrete"): a for a, n in NAMES.items()}}


def value(cell: str) -> float:
    return float(cell.replace("−", "-").replace("*", "").strip())


def runs_render(
    pages, tmp_path, capsys, marker: str, datas: list[dict] | dict, change: tuple[int, str, str], page: str = PAGE
) -> None:
    pages.renders_runs(tmp_path, capsys, page, marker, datas, change)


def one_render(pages, tmp_path, capsys, marker: str, data: dict, change: tuple[str, str], page: str = PAGE) -> None:
    runs_render(pages, tmp_path, capsys, marker, data, (0, *change), page)


# -- the offline benchmark's bench.json ---------------------------------------------------------------------------
def agg(mean: float, std: float = 0.0, n: int = 3) -> dict:
    return {"mean": mean, "std": std, "n": n}


def bench(scene: str, summary: list[dict], datasets: dict | None = None, **config) -> dict:
    """A ``bench.json`` of ``run_bench``'s shape."""
    algos = config.pop("algorithms", list(NAMES))
    return {
        "complete": True,
        "config": {"scene": scene, "seeds": [0, 1, 2], "variants": list(TWINS), "num_envs": 256, **config},
        "algorithms": {a: NAMES[a] for a in algos},
        "datasets": datasets or {},
        "summary": summary,
        "runs": [],
    }


def entry(beh: str, algo: str, bp: dict | None, dy: dict | None) -> dict:
    e = {"behaviour": beh, "algorithm": algo, "seeds": [0, 1, 2], "train_s": agg(20.0)}
    for v, m in zip(TWINS, (bp, dy), strict=True):
        if m is not None:
            e[v] = {"normalized": m, "spl": agg(0.9)}
    return e


def parse_best(cell: str) -> list[tuple[float, float, int, list[str]]]:
    """``80.0 ± 0.5 (BCQ) / 75.5 ± 1.2`` -> per twin (mean, std, n, algorithm keys named)."""
    out = []
    for side in cell.replace("*", "").split(" / "):
        m = re.fullmatch(r"(\S+)(?: ± (\S+))?(?: \(([^)]*)\))?", side.strip())
        names = [KEY[n] for n in m.group(3).split(", ")] if m.group(3) else []
        out.append((value(m.group(1)), float(m.group(2) or 0), 3 if m.group(2) else 1, names))
    return out


def best_entries(beh: str, cell: str, shift: tuple[float, float] = (0.0, 0.0)) -> list[dict]:
    """Summary entries whose best per twin is ``cell`` (the algorithms it names, else BCQ), beside a weaker NFQ;
    ``shift`` moves each twin's mean (a value a difference column needs, unrounded)."""
    (bp, bs, n, bnames), (dy, ds, _, dnames) = parse_best(cell)
    bp, dy = bp + shift[0], dy + shift[1]
    algos = list(dict.fromkeys(bnames + dnames)) or ["bcq"]
    out = []
    for a in algos:
        b = bp if a in bnames or not bnames else bp - 10
        d = dy if a in dnames or not dnames else dy - 10
        out.append(entry(beh, a, agg(b, bs, n), agg(d, ds, n)))
    if "nfq" not in algos:
        out.append(entry(beh, "nfq", agg(bp - 20, 1.0, n), agg(dy - 20, 1.0, n)))
    return out


def pair(cell: str) -> dict:
    """``99.2 / 96.2`` -> ``{twin: {"normalized": ...}}``."""
    return {v: {"normalized": value(x)} for v, x in zip(TWINS, cell.split(" / "), strict=True)}


def behaviour(cell: str) -> dict:
    """A dataset of ``bench.json`` whose behaviour, rolled out, scored ``cell`` (``-``: no single policy)."""
    return {"name": "", "eval": {} if cell == "-" else pair(cell), "steps": 100_096, "episodes": 500}


def tabular(cells: dict[str, str]) -> dict:
    """``{column: "99.2 / 96.2"}`` -> a dataset's tabular row."""
    return {c: pair(cell) for c, cell in cells.items()}


def rows(pages, marker: str) -> list[list[str]]:
    text, block = pages.block_of(PAGE, marker)
    return pages.rows_of(text, block)


def rounding(bp: str, dy: str, lost: str) -> tuple[float, float]:
    """Shifts of two shown means (±0.04) whose difference, unrounded, reads ``lost``."""
    steps = [i / 100 for i in range(-4, 5)]
    for a in steps:
        for b in steps:
            if f"{value(bp) + a - (value(dy) + b):.1f}" == lost:
                return a, b
    raise AssertionError((bp, dy, lost))


# -- the tables ---------------------------------------------------------------------------------------------------
def test_the_logged_families_table_is_the_first_benchmarks_datasets_section(pages, tmp_path, capsys):
    datasets = {}
    for name, steps, episodes, rolled, logged in rows(pages, "offline-logged"):
        beh = name.strip("`").split("/")[-1]
        ev = {} if rolled.startswith("—") else {"blueprint": {"normalized": value(rolled)}, "dynamic": {}}
        datasets[beh] = {
            "name": name.strip("`"),
            "steps": int(steps.replace(" ", "")),
            "episodes": int(episodes.replace(" ", "")),
            "eval": ev,
            "logged_score": value(logged.split(" (")[0]),
        }
    data = bench("cubicle", [], datasets)
    one_render(pages, tmp_path, capsys, "offline-logged", data, ("94.5", "93.1"))


def test_the_dallas_default_benchmark_sits_beside_the_two_earlier_defaults(pages, tmp_path, capsys):
    before, memoryless, default, datasets, tab = [], [], [], {}, {}
    for beh, own, old, mless, auto, ce in rows(pages, "offline-defaults results/offline_bench/dallas-q3-before"):
        before += best_entries(beh, old)
        memoryless += best_entries(beh, mless)
        default += best_entries(beh, auto)
        datasets[beh] = behaviour(own)
        tab[beh] = tabular({"ce-senses": ce})
    datas = [
        bench("dallas-q3", before, datasets),
        bench("dallas-q3", memoryless, datasets, relabel="auto", senses="none"),
        {**bench("dallas-q3", default, datasets, relabel="auto", senses="auto"), "tabular": tab},
    ]
    runs_render(pages, tmp_path, capsys, "offline-defaults results/offline_bench/dallas-q3", datas, (2, "99.2", "97.7"))


def test_the_cubicle_default_benchmark_says_what_its_best_learner_loses_on_the_dynamic_twin(pages, tmp_path, capsys):
    memoryless, default, datasets, tab = [], [], {}, {}
    for beh, own, mless, auto, lost, ce in rows(pages, "offline-defaults results/offline_bench/cubicle"):
        memoryless += best_entries(beh, mless)
        (bp, *_), (dy, *_) = parse_best(auto)
        default += best_entries(beh, auto, rounding(f"{bp:.1f}", f"{dy:.1f}", lost))
        datasets[beh] = behaviour(own)
        tab[beh] = tabular({"ce-senses": ce})
    datas = [
        bench("cubicle", memoryless, datasets, relabel="auto", senses="none"),
        {**bench("cubicle", default, datasets, relabel="auto", senses="auto"), "tabular": tab},
    ]
    runs_render(pages, tmp_path, capsys, "offline-defaults results/offline_bench/cubicle", datas, (0, "74.4", "75.0"))


def relabel_runs(pages, scene: str, marker: str) -> list[dict]:
    """bench_relabel.py's runs holding a table's cells (mixed: the mix ``auto`` itself, else the mix it stands for)."""
    text, block = pages.block_of(PAGE, marker)
    head = [c.strip() for c in text[block.start : block.end].strip().splitlines()[0].strip("|").split("|")]
    runs = []
    for fam, *cells in pages.rows_of(text, block):
        for algo, cell in zip(head[1:], cells, strict=True):
            if not cell:
                continue
            (a, b), (c, d) = (side.split(" → ") for side in cell.strip("*").split(" / "))
            for mix, bp, dy in (("none", a, c), ("auto" if fam == "mixed" else AUTO_MIXES[algo], b, d)):
                runs.append({"scene": scene, "family": fam, "algorithm": algo, "mix": mix, "seed": 0, "n_steps": 4000,
                             "blueprint": {"normalized": value(bp)}, "dynamic": {"normalized": value(dy)}})  # fmt: skip
    return runs


def test_the_relabelling_tables_come_from_bench_relabels_json(pages, tmp_path, capsys):
    m = "offline-relabel results/bench_relabel/bench.json scene="
    data = {"runs": relabel_runs(pages, "cubicle", m + "cubicle") + relabel_runs(pages, "dallas-q3", m + "dallas-q3")}
    one_render(pages, tmp_path, capsys, m + "dallas-q3", data, ("71.3", "70.2"))
    one_render(pages, tmp_path, capsys, m + "cubicle", data, ("98.1", "97.3"))


def test_relabelled_and_not_sit_side_by_side_for_both_scenes(pages, tmp_path, capsys):
    runs = [[] for _ in range(4)]
    for beh, *cells in rows(pages, "offline-relabelling"):
        for i, cell in enumerate(cells):
            runs[i] += best_entries(beh, cell)
    relabel = ({}, {"relabel": "auto", "senses": "none"})
    datas = [
        bench(scene, runs[2 * s + k], **relabel[k]) for s, scene in enumerate(("dallas-q3", "cubicle")) for k in (0, 1)
    ]
    for d in datas:
        d["datasets"] = {beh: behaviour("-") for beh in dict.fromkeys(e["behaviour"] for e in d["summary"])}
    runs_render(pages, tmp_path, capsys, "offline-relabelling", datas, (3, "97.2", "97.6"))


def test_the_memory_window_table_reads_each_benchmarks_seed_0_runs(pages, tmp_path, capsys):
    text, block = pages.block_of(PAGE, "offline-senses")
    algos = [KEY[c.strip()] for c in text[block.start : block.end].strip().splitlines()[0].strip("|").split("|")[1:]]
    runs: dict[tuple[str, str], list[dict]] = {}
    for label, *cells in pages.rows_of(text, block):
        where, senses = label.rsplit(", ", 1)
        scene = "dallas-q3" if where.startswith("Dallas Q3") else "cubicle"
        beh = where.split()[-1]
        for algo, cell in zip(algos, cells, strict=True):
            bp, dy = (value(x) for x in cell.strip("*").split(" / "))
            row = {"behaviour": beh, "algorithm": algo, "seed": 0, "blueprint": {"normalized": bp},
                   "dynamic": {"normalized": dy}}  # fmt: skip
            runs.setdefault((scene, senses), []).append(row)
            runs[scene, senses].append({**row, "seed": 1, "blueprint": {"normalized": 100.0}})  # not shown
    datas = []
    for scene in ("dallas-q3", "cubicle"):
        for senses in ("memoryless", "memory"):
            d = bench(scene, [], {"expert": behaviour("-"), "medium": behaviour("-")},
                      relabel="auto", senses="none" if senses == "memoryless" else "memory")  # fmt: skip
            d["runs"] = runs[scene, senses]
            datas.append(d)
    runs_render(pages, tmp_path, capsys, "offline-senses", datas, (1, "74.1", "75.3"))


def test_the_ogbench_families_merge_each_scenes_deep_and_tabular_benchmarks(pages, tmp_path, capsys):
    deep, tables = {"cubicle": [], "dallas-q3": []}, {"cubicle": {}, "dallas-q3": {}}
    datasets = {"cubicle": {}, "dallas-q3": {}}
    for family, own, best_deep, ce, lcb, ceiling in rows(pages, "offline-ogbench"):
        scene, beh = family.split()
        deep[scene] += [{**e, "seeds": [0]} for e in best_entries(beh, best_deep)]
        datasets[scene][beh] = behaviour(own)
        tables[scene][beh] = tabular({"ce-senses": ce, "lcb-senses": lcb})
        tables[scene][beh]["ceiling"] = {"blueprint": {"normalized": value(ceiling)}}
    datas = []
    for scene in ("cubicle", "dallas-q3"):
        datas.append(bench(scene, deep[scene], datasets[scene], relabel="auto", senses="none", seeds=[0]))
        no_deep = bench(scene, [], datasets[scene], relabel="auto", senses="none", seeds=[0], algorithms=[])
        datas.append({**no_deep, "tabular": tables[scene]})
    runs_render(pages, tmp_path, capsys, "offline-ogbench", datas, (3, "98.2", "98.4"))


def test_the_ogbench_families_with_senses_beside_memoryless(pages, tmp_path, capsys):
    memoryless, senses = [], []
    for family, a, b in rows(pages, "offline-best-learners"):
        beh = family.split()[1]
        memoryless += best_entries(beh, a)
        senses += best_entries(beh, b)
    fams = {b: behaviour("-") for b in ("navigate", "stitch", "explore")}
    datas = [
        bench("dallas-q3", memoryless, fams, relabel="auto", senses="none", seeds=[0]),
        bench("dallas-q3", senses, fams, relabel="auto", senses="auto", seeds=[0]),
    ]
    runs_render(pages, tmp_path, capsys, "offline-best-learners", datas, (1, "80.7", "81.2"))


def test_more_updates_are_one_benchmark_each(pages, tmp_path, capsys):
    summaries: list[list[dict]] = [[], [], []]
    for label, *cells in rows(pages, "offline-updates"):
        beh, name = label.split(", ")
        for i, cell in enumerate(cells):
            if cell != "-":
                bp, dy = (value(x) for x in cell.split(" / "))
                summaries[i].append(entry(beh, KEY[name], agg(bp, n=1), agg(dy, n=1)))
    fams, kw = {"expert": behaviour("-"), "medium": behaviour("-")}, {"senses": "memory", "seeds": [0]}
    datas = [
        bench("dallas-q3", summaries[0], fams, n_steps=4000, **kw),
        bench("dallas-q3", summaries[1], fams, n_steps=12000, algorithms=["bcq", "dqn"], **kw),
        bench("dallas-q3", summaries[2], {"expert": fams["expert"]}, n_steps=24000, algorithms=["bcq", "dqn"], **kw),
    ]
    runs_render(pages, tmp_path, capsys, "offline-updates", datas, (2, "88.7", "89.9"))


def test_the_bf16_benchmark_names_what_auto_put_in_bf16_and_its_gain(pages, tmp_path, capsys):
    fp32, bf16 = [], []
    for beh, a, b, _gain in rows(pages, "offline-precision"):
        fp32 += best_entries(beh, a)
        bf16 += best_entries(beh, b)
    bf16_runs = [{"behaviour": "random", "algorithm": a, "seed": 0, "precision": "bf16" if a in ("bcq", "dqn", "ddqn",
                  "nfq") else "fp32", "batch_size": 512 if a not in ("bc", "cql") else 256} for a in NAMES]  # fmt: skip
    fams = {e["behaviour"]: behaviour("-") for e in fp32}
    datas = [
        bench("dallas-q3", fp32, fams, relabel="auto", senses="auto", precision="fp32", batch_size=256),
        {
            **bench("dallas-q3", bf16, fams, relabel="auto", senses="auto", precision="auto", batch_size=0),
            "runs": bf16_runs,
        },
    ]
    runs_render(pages, tmp_path, capsys, "offline-precision", datas, (1, "86.9", "87.5"))


def scores_bench(pages, marker: str, scene: str, online: dict | None = None) -> dict:
    """A benchmark before relabelling holding both twins' score tables of the page (the bold cell, the best, a hair
    above the others that read the same)."""
    variants = {}
    for v in TWINS:
        text, block = pages.block_of(FIRST, f"{marker} variant={v}")
        head = [c.strip() for c in text[block.start : block.end].strip().splitlines()[0].strip("|").split("|")]
        variants[v] = (head[2:], pages.rows_of(text, block))
    names, _ = variants["blueprint"]
    datasets, summary = {}, {}
    for v, (_, table) in variants.items():
        for beh, own, *cells in table:
            d = datasets.setdefault(beh, behaviour("-"))
            if own != "-":
                d["eval"][v] = {"normalized": value(own)}
            for name, cell in zip(names, cells, strict=True):
                (m, s, n, _), = parse_best(cell)  # fmt: skip
                e = summary.setdefault((beh, KEY[name]), entry(beh, KEY[name], None, None))
                e[v] = {"normalized": agg(m + (0.004 if cell.startswith("**") else 0), s, n)}
    data = bench(scene, list(summary.values()), datasets)
    if online:
        data["online_dqn"] = {v: {"normalized": x, "success_rate": 0.97} for v, x in online.items()}
    return data


def test_the_first_cubicle_benchmarks_score_tables(pages, tmp_path, capsys):
    marker = "offline-bench-scores results/offline_bench/cubicle-before-relabelling/bench.json"
    data = scores_bench(pages, marker, "cubicle")
    one_render(pages, tmp_path, capsys, f"{marker} variant=blueprint", data, ("97.8", "97.1"), FIRST)
    one_render(pages, tmp_path, capsys, f"{marker} variant=dynamic", data, ("27.9", "29.0"), FIRST)


def test_the_first_dallas_benchmarks_score_tables_name_the_online_agent(pages, tmp_path, capsys):
    marker = "offline-scores-online results/offline_bench/dallas-q3-before-relabelling/bench.json"
    data = scores_bench(pages, marker, "dallas-q3", online={"blueprint": 96.9, "dynamic": 93.2})
    one_render(pages, tmp_path, capsys, f"{marker} variant=blueprint", data, ("25.0", "26.0"), FIRST)
    one_render(pages, tmp_path, capsys, f"{marker} variant=dynamic", data, ("17.8", "18.6"), FIRST)
    data["online_dqn"]["dynamic"]["normalized"] = 91.04  # the online agent of a re-run, in the header
    table = pages.results_pages.RENDERERS["offline-scores-online"].render(data, {"variant": "dynamic"})
    assert table.startswith("| dallas-q3 → dynamic (online agent: 91.0) | behaviour itself |")


# -- single offline runs' results.json ----------------------------------------------------------------------------
DEFAULT = {"algorithm": "bcq", "batch_size": 256, "hidden": [256, 256], "lr": 1e-3, "gamma": 0.5,
           "target_update_interval": 500, "transitions": 100_000, "n_steps": 4000, "precision": "fp32",
           "relabel": "auto", "senses": "auto", "logged": ""}  # fmt: skip


def offline_run(scene: str, cells: str | None, train_s: str = "30.0", resolved: dict | None = None, **cfg) -> dict:
    """A ``results.json`` of ``train_offline``: its settings, what they resolved to, its rows (one shielded too); a
    blank ``train_s``: a run whose training seconds the page does not give (left out of the JSON)."""
    config = {**DEFAULT, "scene": scene, **cfg}
    stats = {"n_steps": config["n_steps"], "batch_size": config["batch_size"] or 512, "precision": config["precision"],
             **({"train_s": float(train_s)} if train_s else {}), **(resolved or {})}  # fmt: skip
    rows = []
    for v, x in zip(TWINS, (cells or "- / -").split(" / "), strict=True):
        if x != "-":
            rows += [{"dataset": f"{scene}/{v}", "shield": False, "normalized": value(x)},
                     {"dataset": f"{scene}/{v}", "shield": True, "normalized": 100.0}]  # fmt: skip
    return {"config": {"config": config, "stats": stats}, "results": rows}


ONE_CHANGE = {  # a row's settings, from the page's label
    "lr 3e-3": {"lr": 3e-3},
    "target sync every 100 updates": {"target_update_interval": 100},
    "target sync every 2 000 updates": {"target_update_interval": 2000},
    "γ 0.8": {"gamma": 0.8},
    "hidden 128 × 128": {"hidden": [128, 128]},
    "batch 1 024": {"batch_size": 1024},
    "batch 1 024, lr 3e-3": {"batch_size": 1024, "lr": 3e-3},
    "batch 1 024, hidden 128 × 128": {"batch_size": 1024, "hidden": [128, 128]},
    "batch 2 048": {"batch_size": 2048},
    "12 000 updates": {"n_steps": 12000},
    "24 000 updates": {"n_steps": 24000},
    "1 M logged steps": {"transitions": 1_000_000},
    "1 M logged steps, 12 000 updates": {"transitions": 1_000_000, "n_steps": 12000},
    "1 M logged steps, 24 000 updates": {"transitions": 1_000_000, "n_steps": 24000},
    "1 M logged steps, 48 000 updates": {"transitions": 1_000_000, "n_steps": 48000},
}


def test_one_change_at_a_time_is_a_row_per_setting_of_single_offline_runs(pages, tmp_path, capsys):
    datas = []
    for label, _samples, bcq, bcq_s, dqn, dqn_s in rows(pages, "offline-one-change"):
        cfg = {} if label.startswith("default") else ONE_CHANGE[label]
        datas.append(offline_run("dallas-q3", bcq, bcq_s, **cfg))
        if dqn:
            datas.append(offline_run("dallas-q3", dqn, dqn_s, algorithm="dqn", **cfg))
    runs_render(pages, tmp_path, capsys, "offline-one-change", datas, (17, "83.0", "84.2"))


def test_the_bf16_runs_are_a_row_per_precision_and_batch_they_resolved_to(pages, tmp_path, capsys):
    settings = [
        {},
        {"precision": "auto", "batch_size": 0},
        {"precision": "bf16", "batch_size": 1024},
        {"batch_size": 1024},
    ]
    datas = []
    for cfg, (_label, _samples, bcq, bcq_s, dqn, dqn_s) in zip(
        settings, rows(pages, "offline-run-precision"), strict=True
    ):
        resolved = {"precision": "bf16"} if cfg.get("precision") in ("auto", "bf16") else {}
        for algo, cells, s in (("bcq", bcq, bcq_s), ("dqn", dqn, dqn_s)):
            datas.append(offline_run("dallas-q3", cells, s, resolved, algorithm=algo, **cfg))
    runs_render(pages, tmp_path, capsys, "offline-run-precision", datas, (2, "82.0", "81.1"))


def test_the_first_budget_is_a_grid_of_offline_runs_by_learning_rate_and_updates(pages, tmp_path, capsys):
    text, block = pages.block_of(FIRST, "offline-budget")
    datas = []
    for path in pages.results_pages.paths(block):
        m = re.search(r"budget/(\w+)-(\w+)-lr(\S+?)-n-steps(\d+)/", path)
        family, algo, lr, n = m.group(1), m.group(2), float(m.group(3)), int(m.group(4))
        datas.append(offline_run("cubicle", None, algorithm=algo, lr=lr, n_steps=n,
                                 logged=f"cubicle/blueprint/{family}", relabel="none", senses="none"))  # fmt: skip
    cols = [(3000, 3e-4), (3000, 1e-3), (3000, 3e-3), (5000, 1e-3), (10000, 3e-4), (10000, 1e-3)]
    for family, name, *cells in pages.rows_of(text, block):
        for (n, lr), cell in zip(cols, cells, strict=True):
            if cell:
                (d,) = [d for d in datas if (d["config"]["config"]["logged"].endswith("/" + family)
                        and (d["config"]["config"]["algorithm"], d["config"]["config"]["n_steps"],
                             d["config"]["config"]["lr"]) == (KEY[name], n, lr))]  # fmt: skip
                d["results"] = [{"dataset": "cubicle/blueprint", "shield": False, "normalized": value(cell)}]
    runs_render(pages, tmp_path, capsys, "offline-budget", datas, (0, "71.1", "72.0"), FIRST)
