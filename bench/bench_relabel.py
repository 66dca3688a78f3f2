"""Goal relabelling against the logged targets: normalised score of offline agents trained with each relabelling mix.

    python bench/bench_relabel.py --scenes cubicle dallas-q3 --families expert medium
    python bench/bench_relabel.py --scenes cubicle --families expert --algorithms bc --mixes none future --workers 1
    python bench/bench_relabel.py --families mixed --mixes none auto         # auto: the algorithm's own mix

For every scene, dataset family (``<scene>/blueprint/<family>``, already logged: ``make log SCENE=<scene>
BEHAVIOUR=all``), algorithm and relabelling mix (``--relabel`` of ``make offline``: ``none`` is the logged targets),
one :func:`~dtradar_rl.offline.trainer.train_offline` run with the offline defaults (4 000 updates by default, the
offline benchmark's budget; lr 1e-3, one torch thread), evaluated greedy and unshielded on the 500 seeded pairs
(seed 2024) of the blueprint and the dynamic twin and scored on each twin's normalised scale
(:func:`dtradar_rl.evaluation.normalized.normalized` with :func:`~dtradar_rl.evaluation.normalized.reference_scores`).
Runs go to ``--workers`` spawned processes (one torch thread each). Every finished run is appended to
``results/bench_relabel/runs.jsonl`` (``--out``); a run already there (same scene, family, algorithm, mix, seed,
updates, discount, resampling) is not run again, and ``bench.json`` (``{"runs": [...]}``, every run) and ``bench.md``
are rewritten from all of them; :func:`table` is the results page's table of one scene (the logged targets -> the
``auto`` mix).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path
from typing import Any

KEYS = ("scene", "family", "algorithm", "mix", "seed", "n_steps", "discount", "resample")


def run_one(job: dict[str, Any]) -> dict[str, Any]:
    import torch

    torch.set_num_threads(1)
    from dtradar_rl.evaluation.normalized import normalized, reference_scores
    from dtradar_rl.offline.config import OfflineConfig
    from dtradar_rl.offline.trainer import train_offline
    from dtradar_rl.task.twins import load_dataset

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = OfflineConfig(
            scene=job["scene"],
            algorithm=job["algorithm"],
            logged=f"{job['scene']}/blueprint/{job['family']}",
            seed=job["seed"],
            n_steps=job["n_steps"],
            relabel=job["mix"],
            relabel_discount=job["discount"],
            relabel_resample=job["resample"],
            shield=False,
            latency=False,
            threads=1,
            verbose=False,
            out=str(Path(tmp) / "run"),
        )
        result = train_offline(cfg)
    out = {**job, "train_s": result.train_s, "wall_s": time.perf_counter() - t0}
    for row in result.rows:
        variant = row["dataset"].split("/")[1]
        refs = reference_scores(load_dataset(row["dataset"]), pairs=cfg.pairs, seed=cfg.eval_seed)
        out[variant] = {
            "normalized": normalized(row["spl"], refs),
            "spl": row["spl"],
            "success_rate": row["success_rate"],
        }
    out["relabel"] = result.logged.get("relabel")
    return out


def _key(run: dict[str, Any]) -> tuple:
    return tuple(run[k] for k in KEYS)


#: The page's order of the algorithms and families (those present are shown).
ALGORITHMS = ("bc", "cql", "bcq", "dqn", "ddqn", "nfq")
FAMILIES = ("random", "expert", "medium", "medium-replay", "mixed")


def _auto_run(runs: list[dict[str, Any]], algorithm: str) -> dict[str, Any] | None:
    """The run of ``--relabel auto`` among ``runs`` (the mix ``auto``, else the mix auto stands for)."""
    from dtradar_rl.offline.relabel import AUTO_MIXES

    for mix in ("auto", AUTO_MIXES.get(algorithm)):
        hit = [r for r in runs if r["mix"] == mix]
        if hit:
            return hit[-1]
    return None


def table(data: dict[str, Any], scene: str, bold: bool = True) -> str:
    """The page's table of ``scene``: a row per family, a column per algorithm, each cell the normalised score on
    the logged targets -> with the ``auto`` mix, blueprint / dynamic (blank: not run); ``bold``: the best ``auto``
    blueprint score of each family in bold."""
    sel = [r for r in data["runs"] if r["scene"] == scene]
    algos = [a for a in ALGORITHMS if any(r["algorithm"] == a for r in sel)]
    algos += list(dict.fromkeys(r["algorithm"] for r in sel if r["algorithm"] not in algos))
    fams = [f for f in FAMILIES if any(r["family"] == f for r in sel)]
    fams += list(dict.fromkeys(r["family"] for r in sel if r["family"] not in fams))
    lines = ["| " + " | ".join([scene, *algos]) + " |", "|" + "---|" * (1 + len(algos))]
    for fam in fams:
        cells, best = [], (None, -1)
        for i, a in enumerate(algos):
            runs = [r for r in sel if (r["family"], r["algorithm"]) == (fam, a)]
            none = [r for r in runs if r["mix"] == "none"]
            auto = _auto_run(runs, a)
            if not none or auto is None:
                cells.append("")
                continue
            cells.append(
                " / ".join(
                    f"{none[-1][v]['normalized']:.1f} → {auto[v]['normalized']:.1f}" for v in ("blueprint", "dynamic")
                )
            )
            if best[0] is None or auto["blueprint"]["normalized"] > best[0]:
                best = (auto["blueprint"]["normalized"], i)
        if bold and best[0] is not None:
            cells[best[1]] = f"**{cells[best[1]]}**"
        lines.append("| " + fam + " |" + "".join(f" {c} |" if c else " |" for c in cells))
    return "\n".join(lines) + "\n"


def write_markdown(runs: list[dict[str, Any]], path: Path) -> None:
    """``bench.md``: every mix's score per scene and twin, the results page's table of each scene, then every run's
    seconds; and ``bench.json`` beside it (every run: what :func:`table` reads)."""
    path.with_name("bench.json").write_text(json.dumps({"runs": runs}, indent=2) + "\n")
    lines = []
    for scene in dict.fromkeys(r["scene"] for r in runs):
        for variant in ("blueprint", "dynamic"):
            sel = [r for r in runs if r["scene"] == scene]
            mixes = list(dict.fromkeys(r["mix"] for r in sel))
            lines += [f"**{scene} -> {variant}** (normalised score, seed 0)", ""]
            lines += ["| family | algorithm | " + " | ".join(mixes) + " |", "|---|---|" + "---:|" * len(mixes)]
            for fam in dict.fromkeys(r["family"] for r in sel):
                for algo in dict.fromkeys(r["algorithm"] for r in sel):
                    cells = []
                    for mix in mixes:
                        hit = [r for r in sel if (r["family"], r["algorithm"], r["mix"]) == (fam, algo, mix)]
                        cells.append(f"{hit[-1][variant]['normalized']:.1f}" if hit and variant in hit[-1] else "")
                    if any(cells):
                        lines.append(f"| {fam} | {algo} | " + " | ".join(cells) + " |")
            lines.append("")
    for scene in dict.fromkeys(r["scene"] for r in runs):
        lines += [
            f"**{scene}**: the logged targets → the `auto` mix, blueprint / dynamic",
            "",
            table({"runs": runs}, scene),
            "",
        ]
    lines += ["| scene | family | algorithm | mix | train s | wall s |", "|---|---|---|---|---:|---:|"]
    lines += [
        f"| {r['scene']} | {r['family']} | {r['algorithm']} | {r['mix']} | {r['train_s']:.1f} | {r['wall_s']:.1f} |"
        for r in runs
    ]
    path.write_text("\n".join(lines) + "\n")


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenes", nargs="+", default=["cubicle", "dallas-q3"])
    p.add_argument("--families", nargs="+", default=["expert", "medium"])
    p.add_argument("--algorithms", nargs="+", default=["bc", "cql", "bcq", "dqn"])
    p.add_argument("--mixes", nargs="+", default=["none", "future", "own-future", "ogbench", "own-next"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-steps", type=int, default=4000)
    p.add_argument("--discount", type=float, default=0.9)
    p.add_argument("--resample", default="batch")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", default="results/bench_relabel")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "runs.jsonl"
    runs = [json.loads(line) for line in log.read_text().splitlines() if line.strip()] if log.exists() else []
    done = {_key(r) for r in runs}
    jobs = [
        {
            "scene": s,
            "family": f,
            "algorithm": al,
            "mix": m,
            "seed": a.seed,
            "n_steps": a.n_steps,
            "discount": a.discount if m != "none" else 0.9,
            "resample": a.resample if m != "none" else "batch",
        }
        for s in a.scenes
        for f in a.families
        for m in a.mixes
        for al in a.algorithms
    ]
    jobs = [j for j in jobs if _key(j) not in done]
    print(f"{len(jobs)} runs to do ({len(done)} already in {log}); load average {os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=a.workers, mp_context=get_context("spawn")) as pool:
        futures = [pool.submit(run_one, j) for j in jobs]
        for fut in as_completed(futures):
            r = fut.result()
            runs.append(r)
            with open(log, "a") as f:
                f.write(json.dumps(r) + "\n")
            write_markdown(runs, out / "bench.md")
            scores = "  ".join(f"{v} {r[v]['normalized']:6.1f}" for v in ("blueprint", "dynamic") if v in r)
            print(
                f"[{time.perf_counter() - t0:7.1f}s] {r['scene']} {r['family']} {r['algorithm']} {r['mix']}: {scores}"
                f"  (train {r['train_s']:.1f} s, wall {r['wall_s']:.1f} s, load {os.getloadavg()[0]:.2f})",
                flush=True,
            )
    write_markdown(runs, out / "bench.md")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
