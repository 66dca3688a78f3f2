"""Where d3rlpy's training time goes: updates per second of every offline algorithm under each setting, side by side.

    python bench/bench_offline_speed.py --scene cubicle                       # every section (~15 min on 2 cores)
    python bench/bench_offline_speed.py --sections algorithms --algorithms cql bc
    make bench-offline-speed ARGS="--sections parallel"

Every measurement trains a freshly seeded d3rlpy algorithm (the hyper-parameters of ``make offline``,
:func:`dtradar_rl.offline.trainer.make_algorithm`) for ``--updates`` updates on one logged dataset
(``--logged``, default ``<scene>/blueprint/noisy-shortest``, logged with 100 K steps when it is not in the store) and
times the whole ``fit`` (model building included). The variants of a section run interleaved, ``--rounds`` times, in
a shuffled order per round, so a neighbour's load falls on all of them alike; the tables give the median updates/s,
the ratio to the section's baseline, d3rlpy's own split of an update (minibatch sampling vs the gradient step) and
whether the final weights are bit-identical to the baseline's (same seed).

Sections (``--sections``):

- ``algorithms``: each algorithm with d3rlpy's defaults (file logger, progress bar, timestamped folder, a model
  save every epoch), with the trainer's settings before this bench (all of that off), with the vectorised minibatch
  sampler (:func:`dtradar_rl.offline.trainer.fast_sampling`), and that with 2 torch threads and with the thread
  count ``auto_threads`` picks now;
- ``threads``: whether 2 torch threads give the same weights as 1 (and as 2 again), every algorithm;
- ``epochs``: the number of epochs the updates are split into (1, 10, 100);
- ``evaluators``: d3rlpy's TD-error and initial-state-value evaluators run after every epoch, run once after
  training, or not at all;
- ``parallel``: ``--jobs`` trainings one after the other in this process (1 torch thread) against two spawned
  worker processes with one torch thread each (the layout of ``offline-bench --workers 2``); wall time of the whole
  set, worker start-up (importing d3rlpy, opening the data) included, and each training's own rate;
- ``overhead``: the fixed cost of one :func:`~dtradar_rl.offline.trainer.train_offline` run beside its updates
  (opening the logged data, saving, the evaluation rollouts on both twins) and of one FQE estimate
  (:func:`dtradar_rl.offline.ope.fqe_estimate`), for the full benchmark's wall-time estimate.

Writes ``results/bench_offline_speed.{json,md}`` (``--out``); a run with some sections keeps the others' results
already in the JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import random
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import torch
from bench_offline_speed_report import markdown, plot  # beside this script in bench/ (on its path)

from dtradar_data.core.files import write_atomic
from dtradar_rl.offline.config import ALGORITHMS, OfflineConfig
from dtradar_rl.offline.formats import as_logged, import_d3rlpy, quiet_d3rlpy, to_mdp_dataset
from dtradar_rl.offline.trainer import fast_sampling, make_algorithm
from dtradar_rl.task.runtime import auto_threads, machine

SECTIONS = ("algorithms", "threads", "epochs", "evaluators", "parallel", "overhead")
_DATA: dict[str, Any] = {}  # the opened d3rlpy dataset, per process


def _dataset(logged: str):
    if logged not in _DATA:
        _DATA[logged] = to_mdp_dataset(logged)
    return _DATA[logged]


def digest(algo) -> str:
    """sha256 of every weight of ``algo`` (its torch modules' state dicts, in order)."""
    h = hashlib.sha256()
    for name, module in sorted(algo.impl.modules.get_torch_modules().items()):
        for key, t in module.state_dict().items():
            h.update(f"{name}.{key}".encode())
            h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def train_once(spec: dict[str, Any]) -> dict[str, Any]:
    """One timed training of ``spec``: algorithm, seed, updates, threads and the fit settings to try."""
    d3rlpy = import_d3rlpy()
    torch.set_num_threads(spec["threads"])
    torch.set_flush_denormal(True)
    data = _dataset(spec["logged"])
    d3rlpy.seed(spec["seed"])
    algo = make_algorithm(OfflineConfig(algorithm=spec["algorithm"]))
    per_epoch = max(1, spec["updates"] // spec.get("epochs", 10))
    epochs = spec["updates"] // per_epoch
    n = epochs * per_epoch  # d3rlpy trains whole epochs only
    t0 = time.perf_counter()
    split: dict[str, list[float]] = {"time_sample_batch": [], "time_algorithm_update": []}
    if spec["mode"] == "d3rlpy-defaults":  # what `algo.fit(dataset, n_steps, n_steps_per_epoch)` does
        with tempfile.TemporaryDirectory() as tmp, quiet_d3rlpy(), contextlib.redirect_stderr(io.StringIO()):
            for _, m in algo.fitter(
                data,
                n_steps=n,
                n_steps_per_epoch=per_epoch,
                logger_adapter=d3rlpy.logging.FileAdapterFactory(root_dir=tmp),
            ):
                for k in split:
                    split[k].append(m[k])
    else:
        evaluators = None
        if spec.get("evaluators") in ("during", "after"):
            ev = d3rlpy.metrics
            evaluators = {"td_error": ev.TDErrorEvaluator(), "init_value": ev.InitialStateValueEstimationEvaluator()}
        fast = spec["mode"] != "trainer-before"
        data_used = fast_sampling(data) if fast else data
        with quiet_d3rlpy():
            for _, m in algo.fitter(
                data_used,
                n_steps=n,
                n_steps_per_epoch=per_epoch,
                with_timestamp=False,
                logger_adapter=d3rlpy.logging.NoopAdapterFactory(),
                show_progress=False,
                save_interval=epochs + 1,
                evaluators=evaluators if spec.get("evaluators") == "during" else None,
            ):
                for k in split:
                    split[k].append(m[k])
        if spec.get("evaluators") == "after":
            for e in evaluators.values():
                e(algo, data_used)
    wall = time.perf_counter() - t0
    return {
        "updates_per_s": n / wall,
        "updates": n,
        "wall_s": wall,
        "sample_ms": 1e3 * float(np.mean(split["time_sample_batch"])) if split["time_sample_batch"] else None,
        "update_ms": 1e3 * float(np.mean(split["time_algorithm_update"])) if split["time_algorithm_update"] else None,
        "weights": digest(algo),
        "threads": torch.get_num_threads(),
        "pid": os.getpid(),
    }


def _warm(logged: str) -> None:
    """Imports, the dataset and torch's first-call costs, outside every timing."""
    train_once({"logged": logged, "algorithm": "cql", "seed": 0, "updates": 20, "threads": 1, "mode": "new"})


def interleaved(variants: dict[str, dict[str, Any]], rounds: int, say) -> dict[str, list[dict[str, Any]]]:
    """Every variant ``rounds`` times, in a fresh random order each round."""
    runs: dict[str, list[dict[str, Any]]] = {k: [] for k in variants}
    rng = random.Random(0)
    for r in range(rounds):
        order = list(variants)
        rng.shuffle(order)
        for k in order:
            res = train_once(variants[k])
            runs[k].append(res)
            say(f"  round {r + 1}/{rounds} {k:<40} {res['updates_per_s']:7.1f} updates/s")
    return runs


def summarize(runs: dict[str, list[dict[str, Any]]], baseline: str) -> list[dict[str, Any]]:
    base = statistics.median(x["updates_per_s"] for x in runs[baseline])
    base_w, base_n = runs[baseline][0]["weights"], runs[baseline][0]["updates"]
    rows = []
    for k, rs in runs.items():
        ups = [x["updates_per_s"] for x in rs]
        med = statistics.median(ups)
        sample = [x["sample_ms"] for x in rs if x["sample_ms"] is not None]
        update = [x["update_ms"] for x in rs if x["update_ms"] is not None]
        rows.append(
            {
                "variant": k,
                "updates_per_s": med,
                "min": min(ups),
                "max": max(ups),
                "ratio": med / base,
                "sample_ms": statistics.median(sample) if sample else None,
                "update_ms": statistics.median(update) if update else None,
                # None: a different number of updates, not comparable (see the determinism section)
                "same_weights": all(x["weights"] == base_w for x in rs) if rs[0]["updates"] == base_n else None,
                "threads": rs[0]["threads"],
                "n": len(rs),
            }
        )
    return rows


def section_algorithms(args, say) -> dict[str, Any]:
    auto = auto_threads()
    out = {"auto_threads": auto, "per_algorithm": {}}
    for algo in args.algorithms:
        say(f"algorithms: {algo}")
        common = {"logged": args.logged, "algorithm": algo, "seed": 0, "updates": args.updates}
        variants = {
            "d3rlpy defaults (logging on), 1 thread": {**common, "mode": "d3rlpy-defaults", "threads": 1},
            "trainer before (logging off), 1 thread": {**common, "mode": "trainer-before", "threads": 1},
            "+ vectorised sampler, 1 thread": {**common, "mode": "new", "threads": 1},
            # a third of the updates: two threads run several times slower whenever another process holds a core
            "+ vectorised sampler, 2 threads": {**common, "mode": "new", "threads": 2, "updates": args.updates // 3},
        }
        if auto not in (1, 2):  # auto_threads picks 1 or 2 on this 2-core machine: already measured
            variants[f"+ vectorised sampler, auto threads ({auto})"] = {**common, "mode": "new", "threads": auto}
        out["per_algorithm"][algo] = summarize(
            interleaved(variants, args.rounds, say), "trainer before (logging off), 1 thread"
        )
    return out


def section_threads(args, say) -> dict[str, Any]:
    """Whether the thread count changes the weights: every algorithm, ``--updates // 10`` updates, 1 and 2 threads."""
    n = max(10, args.updates // 10)
    rows = []
    for algo in args.algorithms:
        spec = {"logged": args.logged, "algorithm": algo, "seed": 0, "updates": n, "mode": "new"}
        one, two, two_again = (train_once({**spec, "threads": t}) for t in (1, 2, 2))
        rows.append(
            {
                "algorithm": algo,
                "updates": n,
                "same_weights_1_vs_2": one["weights"] == two["weights"],
                "same_weights_2_vs_2": two["weights"] == two_again["weights"],
                "updates_per_s_1": one["updates_per_s"],
                "updates_per_s_2": statistics.median([two["updates_per_s"], two_again["updates_per_s"]]),
            }
        )
        say(f"  {algo}: 1 vs 2 threads same weights {rows[-1]['same_weights_1_vs_2']}")
    return {"rows": rows}


def section_epochs(args, say) -> dict[str, Any]:
    common = {"logged": args.logged, "algorithm": "cql", "seed": 0, "updates": args.updates, "threads": 1}
    variants = {f"{e} epoch(s)": {**common, "mode": "new", "epochs": e} for e in (1, 10, 100)}
    return {"algorithm": "cql", "rows": summarize(interleaved(variants, args.rounds, say), "10 epoch(s)")}


def section_evaluators(args, say) -> dict[str, Any]:
    common = {"logged": args.logged, "algorithm": "cql", "seed": 0, "updates": args.updates, "threads": 1}
    variants = {
        "no evaluators": {**common, "mode": "new"},
        "TD error + initial value after each of 10 epochs": {**common, "mode": "new", "evaluators": "during"},
        "TD error + initial value once, after training": {**common, "mode": "new", "evaluators": "after"},
    }
    return {"algorithm": "cql", "rows": summarize(interleaved(variants, args.rounds, say), "no evaluators")}


def _init_worker() -> None:
    torch.set_num_threads(1)


def section_parallel(args, say) -> dict[str, Any]:
    algos = [args.algorithms[i % len(args.algorithms)] for i in range(args.jobs)]
    specs = [
        {"logged": args.logged, "algorithm": a, "seed": i, "updates": args.updates, "threads": 1, "mode": "new"}
        for i, a in enumerate(algos)
    ]
    # no "serial, 2 threads": the algorithms and threads sections show it several times slower on a shared machine
    layouts = ("serial, 1 thread", "2 processes x 1 thread")
    results: dict[str, list[dict[str, Any]]] = {k: [] for k in layouts}
    rng = random.Random(1)
    for r in range(args.rounds):
        order = list(layouts)
        rng.shuffle(order)
        for layout in order:
            t0 = time.perf_counter()
            if layout.startswith("serial"):
                rows = [train_once(s) for s in specs]
            else:
                with ProcessPoolExecutor(2, mp_context=get_context("spawn"), initializer=_init_worker) as pool:
                    rows = list(pool.map(train_once, specs))
            wall = time.perf_counter() - t0
            results[layout].append(
                {
                    "wall_s": wall,
                    "weights": [x["weights"] for x in rows],
                    "job_updates_per_s": [x["updates_per_s"] for x in rows],
                    "pids": sorted({x["pid"] for x in rows}),
                }
            )
            say(f"  round {r + 1}/{args.rounds} {layout:<24} {wall:6.1f} s for {len(specs)} x {args.updates} updates")
    base = statistics.median(x["wall_s"] for x in results["serial, 1 thread"])
    ref = results["serial, 1 thread"][0]["weights"]
    rows = []
    for layout, rs in results.items():
        med = statistics.median(x["wall_s"] for x in rs)
        rows.append(
            {
                "layout": layout,
                "wall_s": med,
                "min": min(x["wall_s"] for x in rs),
                "updates_per_s": len(specs) * args.updates / med,
                "speedup": base / med,
                # each training's own rate (start-up of the workers excluded)
                "job_updates_per_s": statistics.median(v for x in rs for v in x["job_updates_per_s"]),
                "processes": len(rs[0]["pids"]),
                "same_weights": all(x["weights"] == ref for x in rs),
            }
        )
    return {"jobs": [f"{s['algorithm']} seed {s['seed']}" for s in specs], "updates": args.updates, "rows": rows}


def section_overhead(args, say) -> dict[str, Any]:
    """One train_offline run's fixed costs at a tiny update count, and an FQE estimate's cost per update."""
    from dtradar_rl.offline.trainer import train_offline

    torch.set_num_threads(1)
    logged = as_logged(args.logged)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for k in range(args.rounds):
            cfg = OfflineConfig(
                scene=args.scene, algorithm="cql", n_steps=100, threads=1, shield=False, verbose=False, out=f"{tmp}/{k}"
            )
            r = train_offline(cfg, dataset=logged)
            rows.append({"wall_s": r.wall_s, "train_s": r.train_s, "fixed_s": r.wall_s - r.train_s})
            say(f"  train_offline, 100 updates: {r.wall_s:.1f} s, of which {r.wall_s - r.train_s:.1f} s not updates")
        out["train_offline_100_updates"] = rows
        out["fixed_s"] = statistics.median(x["fixed_s"] for x in rows)
        try:
            from dtradar_rl.offline.ope import fqe_estimate
        except ImportError:  # pragma: no cover - before the OPE module exists
            return out
        fq = []
        for _ in range(args.rounds):
            t0 = time.perf_counter()
            fqe_estimate(r.policy, logged, n_steps=args.updates, seed=0, gamma=cfg.gamma)
            fq.append(time.perf_counter() - t0)
            say(f"  FQE, {args.updates} updates: {fq[-1]:.1f} s")
        out["fqe"] = {"updates": args.updates, "wall_s": fq, "updates_per_s": args.updates / statistics.median(fq)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="cubicle")
    ap.add_argument("--logged", default="", help="logged dataset (default <scene>/blueprint/noisy-shortest)")
    ap.add_argument("--sections", nargs="+", default=list(SECTIONS), choices=SECTIONS)
    ap.add_argument("--algorithms", nargs="+", default=list(ALGORITHMS), choices=list(ALGORITHMS))
    ap.add_argument("--updates", type=int, default=300, help="updates per measurement")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved repetitions of every variant")
    ap.add_argument("--jobs", type=int, default=4, help="trainings in the parallel section")
    ap.add_argument("--out", default="results/bench_offline_speed", help="output path without extension")
    args = ap.parse_args(argv)
    say = lambda s: print(s, flush=True)
    if not args.logged:
        from dtradar_rl.offline.logged import LogConfig, log_dataset
        from dtradar_rl.task.twins import load_dataset

        lc = LogConfig(scene=args.scene, behaviour="noisy-shortest", steps=100_000, minari=False, verbose=False)
        args.logged = str(log_dataset(lc, load_dataset(f"{args.scene}/blueprint")).name)
    say(f"warming up on {args.logged}")
    _warm(args.logged)
    out = Path(args.out)
    json_path = out.with_suffix(".json")
    result: dict[str, Any] = {}
    if json_path.is_file():
        old = json.loads(json_path.read_text())
        if old.get("logged") == args.logged:  # the other sections measured on the same data stay
            result = old
    d3rlpy = import_d3rlpy()
    result.update(
        {
            "logged": args.logged,
            "machine": machine(),
            "versions": {"d3rlpy": d3rlpy.__version__, "torch": torch.__version__},
            "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
        }
    )
    result.setdefault("sections", {})
    fns = {
        "algorithms": section_algorithms,
        "threads": section_threads,
        "epochs": section_epochs,
        "evaluators": section_evaluators,
        "parallel": section_parallel,
        "overhead": section_overhead,
    }
    for name in args.sections:
        say(f"section {name}")
        t0 = time.perf_counter()
        load = machine().get("load_average")
        got = {**fns[name](args, say), "wall_s": time.perf_counter() - t0}
        got.update(updates=args.updates, rounds=args.rounds, load_average=load, command=result["command"])
        if name == "algorithms" and "algorithms" in result["sections"]:  # algorithms measured in another run stay
            got["per_algorithm"] = {**result["sections"]["algorithms"]["per_algorithm"], **got["per_algorithm"]}
        result["sections"][name] = got
        out.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(json_path, json.dumps(result, indent=2) + "\n")
        write_atomic(out.with_suffix(".md"), markdown(result))
    png = plot(result, out.with_suffix(".png"))
    say(markdown(result))
    if png:
        say(f"results: {json_path}, {out.with_suffix('.md')}, {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
