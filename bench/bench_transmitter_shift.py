"""What a dynamic twin changes per transmitter, and what those changes cost the agents and the planner.

A dynamic twin (the blueprint plus movable objects) changes what a robot hears wherever the objects move a path. With
several transmitters each one's paths change in their own places, so the observation shifts in more cells than with
one. This script measures, for ``--scene`` (default ``dallas-3tx-q3``, Dallas Q3 with three transmitters):

1. per transmitter, the share of the cells free in both twins whose total path gain moved by more than
   ``--threshold-db`` or that became heard or silent, and the share where any transmitter's did;
2. every ``--checkpoints`` model (trained on the blueprint) and the fingerprint planner, evaluated on the dynamic twin
   as it is and with every transmitter's features but transmitter 0's put back to the blueprint's (the *restored*
   twin: the dynamic twin as a one-transmitter deployment would see it change). The difference is what the extra
   transmitters' changed features cost.

``--one`` names the same twin with one transmitter (default ``dallas-q3``) for its changed share beside. Writes
``results/<name>.{json,md,png}``; the same 500 seeded pairs (seed 2024) as ``python -m dtradar_rl eval``.

    python bench/bench_transmitter_shift.py --checkpoints runs/dallas-3tx-q3/*/model.pt
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import write_atomic
from dtradar_data.core.schema import TX_CELL_COLUMNS, tx_column
from dtradar_rl.agents.planner import FingerprintPlanner
from dtradar_rl.evaluation.evaluate import evaluate
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.plots import _save, plt


def _gain(ds: Dataset, k: int) -> np.ndarray:
    return np.array(ds.table.column(tx_column("path_gain_db", k)).to_numpy(zero_copy_only=False), dtype=float)


def changed_cells(blueprint: Dataset, dynamic: Dataset, k: int, threshold_db: float) -> np.ndarray:
    """Per cell (row-major): transmitter ``k``'s total path gain moved by more than ``threshold_db`` between the
    twins, or the cell is heard in one and silent in the other."""
    gb, gd = _gain(blueprint, k), _gain(dynamic, k)
    hb, hd = ~np.isnan(gb), ~np.isnan(gd)
    with np.errstate(invalid="ignore"):
        return (hb != hd) | (hb & hd & (np.abs(gb - gd) > threshold_db))


def restored(blueprint: Dataset, dynamic: Dataset) -> Dataset:
    """``dynamic`` with transmitters 1..K-1's columns taken from ``blueprint`` in every cell free in both (the
    dynamic twin's own values where its objects stand)."""
    free = ~blueprint.blocked.ravel() & ~dynamic.blocked.ravel()
    table = dynamic.table
    for k in range(1, dynamic.transmitters):
        for name in TX_CELL_COLUMNS:
            col = tx_column(name, k)
            values = np.array(table.column(col).to_pylist(), dtype=object)
            values[free] = np.array(blueprint.table.column(col).to_pylist(), dtype=object)[free]
            i = table.column_names.index(col)
            table = table.set_column(i, col, pa.array(list(values), type=table.schema.field(col).type))
    return dataclasses.replace(dynamic, table=table)


def shares(blueprint: Dataset, dynamic: Dataset, threshold_db: float) -> dict[str, float]:
    """The changed share of the cells free in both twins, per transmitter (``tx0``...) and for ``any``."""
    both = ~blueprint.blocked.ravel() & ~dynamic.blocked.ravel()
    per = [changed_cells(blueprint, dynamic, k, threshold_db)[both] for k in range(dynamic.transmitters)]
    out = {f"tx{k}": float(c.mean()) for k, c in enumerate(per)}
    out["any"] = float(np.any(per, axis=0).mean())
    out["free_cells"] = int(both.sum())
    return out


def _case(policy, ds: Dataset, pairs: int) -> dict[str, float]:
    m, _ = evaluate(policy, ds, pairs=pairs, latency=False)
    return {"success": m.success_rate, "spl": m.spl, "collisions": m.collisions}


def run(args) -> dict:
    torch.set_num_threads(1)
    bp, dyn = load_dataset(f"{args.scene}/blueprint"), load_dataset(f"{args.scene}/dynamic")
    if dyn.transmitters < 2:
        sys.exit(f"error: {args.scene} has one transmitter; name a twin with several (e.g. dallas-3tx-q3)")
    result = {"scene": args.scene, "threshold_db": args.threshold_db, "changed": shares(bp, dyn, args.threshold_db)}
    if args.one:
        result["one"] = args.one
        result["changed_one"] = shares(
            load_dataset(f"{args.one}/blueprint"), load_dataset(f"{args.one}/dynamic"), args.threshold_db
        )
    fixed = restored(bp, dyn)
    agents = [(Path(p).parent.name, load_policy(p)) for p in args.checkpoints]
    if not args.no_planner:
        agents.append(("planner", FingerprintPlanner(bp)))
    rows = []
    for name, policy in agents:
        row = {"agent": name, "dynamic": _case(policy, dyn, args.pairs), "restored": _case(policy, fixed, args.pairs)}
        print(
            f"{name:24s} dynamic SPL {row['dynamic']['spl']:.3f}  restored SPL {row['restored']['spl']:.3f}",
            flush=True,
        )
        rows.append(row)
    result["rows"] = rows
    result["command"] = "python bench/bench_transmitter_shift.py " + " ".join(sys.argv[1:])
    result["machine"] = machine()
    return result


def _markdown(r: dict) -> str:
    ch = r["changed"]
    txs = [k for k in ch if k.startswith("tx")]
    lines = [
        f"## What {r['scene']}'s dynamic twin changes per transmitter, and what it costs",
        "",
        f"`{r['command']}`",
        "",
        f"Cells free in both twins ({ch['free_cells']}) whose path gain moved by more than {r['threshold_db']} dB or "
        "became heard or silent:",
        "",
        "| twin | " + " | ".join(txs) + " | any |",
        "|---|" + "---:|" * (len(txs) + 1),
        f"| {r['scene']} | " + " | ".join(f"{ch[k]:.3f}" for k in txs) + f" | {ch['any']:.3f} |",
    ]
    if "changed_one" in r:
        one = r["changed_one"]
        lines.append(f"| {r['one']} | {one['tx0']:.3f} |" + " - |" * (len(txs) - 1) + f" {one['any']:.3f} |")
    lines += [
        "",
        "On the dynamic twin as it is, and *restored* (every transmitter but 0 with the blueprint's features):",
        "",
        "| agent | dynamic: success / SPL / collisions | restored: success / SPL / collisions | SPL difference |",
        "|---|---|---|---:|",
    ]
    for row in r["rows"]:
        d, f = row["dynamic"], row["restored"]
        lines.append(
            f"| {row['agent']} | {d['success']:.3f} / {d['spl']:.3f} / {d['collisions']:.2f} | "
            f"{f['success']:.3f} / {f['spl']:.3f} / {f['collisions']:.2f} | {f['spl'] - d['spl']:+.3f} |"
        )
    return "\n".join(lines) + "\n"


def _plot(r: dict, path: Path) -> Path:
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    ch = r["changed"]
    keys = [k for k in ch if k.startswith("tx")] + ["any"]
    a.bar(keys, [ch[k] for k in keys], color="tab:blue", label=r["scene"])
    if "changed_one" in r:
        a.bar(["one tx"], [r["changed_one"]["any"]], color="tab:orange", label=r["one"])
    a.set_ylabel("share of free cells changed")
    a.legend(fontsize=8)
    names = [row["agent"] for row in r["rows"]]
    x = np.arange(len(names))
    b.bar(x - 0.2, [row["dynamic"]["spl"] for row in r["rows"]], 0.4, label="dynamic")
    b.bar(x + 0.2, [row["restored"]["spl"] for row in r["rows"]], 0.4, label="restored")
    b.set_xticks(x, names, rotation=30, fontsize=8)
    b.set_ylabel("SPL")
    b.legend(fontsize=8)
    fig.suptitle("what the dynamic twin changes per transmitter, and what it costs")
    fig.tight_layout()
    return _save(fig, path)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="dallas-3tx-q3", help="a twin with several transmitters and a dynamic variant")
    ap.add_argument("--one", default="dallas-q3", help="the same twin with one transmitter ('' = none)")
    ap.add_argument("--checkpoints", nargs="*", default=[], help="model.pt files trained on the blueprint (globs too)")
    ap.add_argument("--no-planner", action="store_true")
    ap.add_argument("--pairs", type=int, default=500)
    ap.add_argument("--threshold-db", type=float, default=1.0)
    ap.add_argument("--out", default="results")
    ap.add_argument("--name", default="bench_transmitter_shift")
    args = ap.parse_args(argv)
    args.checkpoints = [p for pattern in args.checkpoints for p in sorted(glob.glob(pattern)) or [pattern]]
    r = run(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / f"{args.name}.json", json.dumps(r, indent=2))
    write_atomic(out / f"{args.name}.md", _markdown(r))
    _plot(r, out / f"{args.name}.png")
    print(f"results: {out / args.name}.json, .md, .png")


if __name__ == "__main__":
    main()
