"""``make paper``: regenerate the paper's tables and figures from the built datasets into one report folder.

    python -m dtradar_rl paper --scenes cubicle meeting        # -> runs/paper/report.md, report.json, figures/*.png

For every scene: the datasets' sizes (Tables II and V), their coverage maps (Figs. 5 and 7), the paper's agent
trained on the blueprint with the scene's Table VI pair (training curves, Figs. 9, 11-16, 18-21; Table VI), its
inference path on the blueprint and dynamic twins (Figs. 10, 22-24); per city, goal-conditioned agents per quadrant
evaluated on every quadrant (Fig. 17); and the training time (Table VII). The paper's number stands beside ours
wherever it gives one. Datasets that are not built are named with the command that builds them; the rest goes on.
A trained run whose config is unchanged is reused (``--retrain`` trains again).
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError
from dtradar_data.core.files import write_atomic
from dtradar_rl.evaluation.evaluate import cross_matrix
from dtradar_rl.evaluation.fixed_pair import evaluate_pair
from dtradar_rl.experiments.paper_report import render
from dtradar_rl.task.config import Config, ConfigError, check_device
from dtradar_rl.task.pairs import paper_pair
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import is_synthetic, load_dataset
from dtradar_rl.train.checkpoints import load_policy
from dtradar_rl.train.config import DQNConfig, config_for
from dtradar_rl.train.dqn import train
from dtradar_rl.viz.figures import plot_bars, plot_episode_curves
from dtradar_rl.viz.plots import plot_matrix, plot_paths

DEFAULT_SCENES = (
    "cubicle",
    "meeting",
    "dallas-q1",
    "dallas-q2",
    "dallas-q3",
    "dallas-q4",
    "houston-q1",
    "houston-q2",
    "houston-q3",
    "houston-q4",
)

_QUADRANT = re.compile(r"^(.+)-q(\d)$")


@dataclass(frozen=True)
class PaperConfig(Config):
    """Regenerate the paper's tables and figures from built datasets into one report folder."""

    scenes: tuple[str, ...] = DEFAULT_SCENES
    """scenes to report on (city quadrants: dallas-q1 ... houston-q4; synthetic-<nx>x<ny> for a quick run)"""
    out: str = str(run_dir("paper"))
    """report folder: report.md, report.json, figures/, and the trained runs under train/"""
    episodes: int = 0
    """training episodes of the paper's agent (0 = the paper's: 500 indoor, 80 outdoor)"""
    seed: int = 0
    """seed of every training run"""
    cross: bool = True
    """train a goal-conditioned agent per city quadrant and evaluate it on every quadrant (Fig. 17)"""
    cross_scenes: tuple[str, ...] = ()
    """also one cross matrix over exactly these scenes (default: only each city's built quadrants)"""
    cross_preset: str = "tuned"
    """preset of the goal-conditioned agents of the cross matrix"""
    cross_steps: int = 600_000
    """training budget (environment steps) of each goal-conditioned agent"""
    cross_pairs: int = 500
    """seeded random (start, target) pairs per cell of the cross matrix"""
    retrain: bool = False
    """train again even where the report folder holds a finished run with the same config"""
    threads: int = 0
    """torch CPU threads (0 = auto)"""
    device: str = "cpu"
    """torch device"""

    def validate(self) -> PaperConfig:
        if not self.scenes:
            raise ConfigError("--scenes is empty", hint="e.g. --scenes cubicle meeting")
        for name in ("episodes", "cross_steps", "cross_pairs", "threads"):
            if getattr(self, name) < (1 if name in ("cross_steps", "cross_pairs") else 0):
                raise ConfigError(f"--{name.replace('_', '-')} is out of range: {getattr(self, name)}")
        check_device(self.device)
        config_for(self.cross_preset)  # an unknown preset fails here, before anything trains
        return self


@dataclass
class Report:
    """What :func:`run_paper` found and measured; ``report.json`` is this, ``report.md`` renders it."""

    config: dict[str, Any]
    machine: dict[str, Any]
    missing: list[dict[str, str]] = field(default_factory=list)
    datasets: list[dict[str, Any]] = field(default_factory=list)
    coverage: list[dict[str, str]] = field(default_factory=list)
    training: list[dict[str, Any]] = field(default_factory=list)
    inference: list[dict[str, Any]] = field(default_factory=list)
    cross: list[dict[str, Any]] = field(default_factory=list)
    wall_s: float = 0.0


# -- helpers ---------------------------------------------------------------------------------------------------------
class _Progress:
    def __init__(self):
        self.t0 = time.perf_counter()
        self.loads: list[float] = []

    def __call__(self, msg: str) -> None:
        self.loads.append(os.getloadavg()[0])
        print(f"[paper {time.perf_counter() - self.t0:7.1f}s] {msg}", flush=True)


def machine_info() -> dict[str, Any]:
    """The machine the times were measured on (:func:`dtradar_rl.task.runtime.machine`), with the 1-minute load
    at the start."""
    m = machine()
    return {**m, "load_avg_start": (m["load_average"] or [0.0])[0]}


def expected_twins(scene: str) -> list[str]:
    """Variants a scene has (blueprint, and dynamic where its scene file defines one)."""
    if is_synthetic(scene):
        return ["blueprint", "dynamic"]
    from dtradar_data.scenes import build_targets

    try:
        return [v for _, v in build_targets(scene)]
    except DtradarError:
        return ["blueprint"]


def build_command(scene: str) -> str:
    if scene.startswith("houston"):
        return f"make dataset SCENE={scene}   (downloads OpenStreetMap; offline: OSM=<file>)"
    return f"make dataset SCENE={scene}"


def _same_run(cfg: DQNConfig, retrain: bool) -> bool:
    """A finished run with exactly this config is in ``cfg.out_dir``."""
    d = cfg.out_dir
    if retrain or not (d / "model.pt").is_file() or not (d / "config.json").is_file():
        return False
    try:
        return json.loads((d / "config.json").read_text()) == json.loads(json.dumps(cfg.to_dict()))
    except (OSError, ValueError):
        return False


def _train_or_reuse(cfg: DQNConfig, ds: Dataset, retrain: bool, say) -> tuple[Path, bool]:
    if _same_run(cfg, retrain):
        say(f"  reusing {cfg.out_dir / 'model.pt'} (same config; --retrain trains again)")
        return cfg.out_dir / "model.pt", True
    return train(cfg, dataset=ds).checkpoint, False


def read_curves(path: Path) -> list[tuple]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))[1:]
    return [(int(r[0]), int(r[1]), float(r[2]), int(r[3]), int(r[4]), r[5] in ("True", "1")) for r in rows]


def _size_on_disk(ds: Dataset) -> int | None:
    if ds.path is None:
        return None
    return sum(f.stat().st_size for f in Path(ds.path).iterdir() if f.is_file())


# -- the report --------------------------------------------------------------------------------------------------
def run_paper(cfg: PaperConfig) -> Report:
    cfg = cfg.validate()
    say = _Progress()
    out, figs = Path(cfg.out), Path(cfg.out) / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    report = Report(config=asdict(cfg), machine=machine_info())

    say(f"datasets of {len(cfg.scenes)} scene(s)")
    twins: dict[str, Dataset] = {}
    for scene in cfg.scenes:
        for variant in expected_twins(scene):
            name = f"{scene}/{variant}"
            try:
                twins[name] = load_dataset(name)
            except DtradarError as e:
                report.missing.append({"dataset": name, "command": build_command(scene), "why": e.message})
                say(f"  {name}: not built, skipped -- build it with: {build_command(scene)}")
    for name, ds in twins.items():
        free = int((~ds.blocked).sum())
        report.datasets.append(
            {
                "dataset": name,
                "nx": ds.shape[1],
                "ny": ds.shape[0],
                "cell_m": ds.grid_info.cell_m,
                "rows": ds.table.num_rows,
                "free": free,
                "bytes": _size_on_disk(ds),
                "version": ds.version,
            }
        )
        png = figs / f"coverage_{name.replace('/', '_')}.png"
        src = Path(ds.path) / "coverage.png" if ds.path else None
        if src is not None and src.is_file():
            shutil.copyfile(src, png)
            how = "the dataset's coverage.png (RadioMapSolver)"
        else:
            plot_paths(ds, [], png, title=f"{name}: path gain per cell (from the table)")
            how = "drawn from the table's path_gain_db"
        report.coverage.append({"dataset": name, "png": png.name, "source": how})

    for scene in cfg.scenes:
        bp = twins.get(f"{scene}/blueprint")
        if bp is None:
            continue
        say(f"training the paper's agent on {scene}/blueprint (Table VI pair)")
        tcfg = config_for(
            "paper",
            scene=scene,
            seed=cfg.seed,
            threads=cfg.threads,
            device=cfg.device,
            out=str(out / "train" / scene / "paper"),
            **({"episodes": cfg.episodes} if cfg.episodes else {}),
        )
        ckpt, reused = _train_or_reuse(tcfg, bp, cfg.retrain, say)
        policy = load_policy(ckpt, cfg.device)
        stats, pair = policy.meta["stats"], policy.meta["stats"]["pair"]
        episodes = read_curves(ckpt.parent / "curves.csv")
        reached = [e for e in episodes if e[5]]
        best = min(reached, key=lambda e: (e[3], e[0])) if reached else None
        near = next((e for e in reached if e[3] <= 1.1 * pair["shortest"]), None)
        row = paper_pair(scene)
        png = figs / f"training_{scene}.png"
        plot_episode_curves(
            episodes,
            png,
            shortest=pair["shortest"],
            paper_min=row.min_steps if row else None,
            title=f"{scene}/blueprint: the paper's agent, pair {pair['start']} -> {pair['target']}",
        )
        entry = {
            "scene": scene,
            "png": png.name,
            "pair": pair,
            "reused": reused,
            "episodes": stats["episodes"],
            "env_steps": stats["env_steps"],
            "updates": stats["updates"],
            "wall_s": stats["wall_s"],
            "reached": len(reached),
            "min_steps": best[3] if best else None,
            "min_episode": best[0] + 1 if best else None,
            "first_within_10pct": near[0] + 1 if near else None,
            "paper": asdict(row) if row else None,
        }
        for variant in ("blueprint", "dynamic"):
            ds = twins.get(f"{scene}/{variant}")
            if ds is None:
                continue
            r, placed, roll = evaluate_pair(policy, ds, device=cfg.device)
            png = figs / f"paths_{scene}_{variant}.png"
            verdict = f"reached in {int(r['steps'])} steps" if r["success_rate"] else f"not reached ({placed.cap} cap)"
            plot_paths(
                ds,
                roll.paths,
                png,
                successes=list(roll.success),
                title=f"{ds.name}: the paper's agent, {verdict}; shortest {placed.shortest}"
                + (f"; paper: {row.min_steps} (its grid)" if row else ""),
            )
            report.inference.append(
                {
                    "scene": scene,
                    "variant": variant,
                    "png": png.name,
                    "reached": bool(r["success_rate"]),
                    "steps": int(r["steps"]),
                    "path_length": int(r["path_length"]),
                    "collisions": int(r["collisions"]),
                    "shortest": placed.shortest,
                    "start": placed.start,
                    "target": placed.target,
                }
            )
        greedy = next((i for i in report.inference if i["scene"] == scene and i["variant"] == "blueprint"), None)
        entry["greedy_steps"] = greedy["steps"] if greedy and greedy["reached"] else None
        report.training.append(entry)
        say(
            f"  {scene}: {entry['episodes']} episodes, {entry['env_steps']} env steps, {entry['wall_s']:.0f} s; "
            f"min steps {entry['min_steps']} (episode {entry['min_episode']}), shortest {pair['shortest']}"
        )

    if cfg.cross:
        for group, scenes in cross_groups(cfg, twins):
            say(
                f"cross-quadrant matrix of {group}: goal-conditioned agents ({cfg.cross_preset}, "
                f"{cfg.cross_steps:,} steps each) on {', '.join(scenes)}"
            )
            report.cross.append(_cross(cfg, group, scenes, twins, out, figs, say))

    report.wall_s = time.perf_counter() - say.t0
    report.machine["load_avg_max"] = round(max(say.loads + [os.getloadavg()[0]]), 2)
    report.machine["load_avg_end"] = round(os.getloadavg()[0], 2)
    write_atomic(out / "report.json", json.dumps(asdict(report), indent=2, default=str) + "\n")
    write_atomic(out / "report.md", render(report))
    say(f"report: {out / 'report.md'} ({report.wall_s:.0f} s)")
    return report


def cross_groups(cfg: PaperConfig, twins: dict[str, Dataset]) -> list[tuple[str, list[str]]]:
    """Each city with at least two built quadrants among ``--scenes``, plus ``--cross-scenes`` as one group."""
    cities: dict[str, list[str]] = {}
    for scene in cfg.scenes:
        m = _QUADRANT.match(scene)
        if m and f"{scene}/blueprint" in twins:
            cities.setdefault(m.group(1), []).append(scene)
    groups = [(city, sorted(s)) for city, s in cities.items() if len(s) >= 2]
    if cfg.cross_scenes:
        groups.append(("custom", list(cfg.cross_scenes)))
    return groups


def _cross(
    cfg: PaperConfig, group: str, scenes: list[str], twins: dict[str, Dataset], out: Path, figs: Path, say
) -> dict[str, Any]:
    datasets = {s: twins.get(f"{s}/blueprint") or load_dataset(f"{s}/blueprint") for s in scenes}
    policies, own, times = {}, {}, {}
    for s in scenes:
        tcfg = config_for(
            cfg.cross_preset,
            scene=s,
            seed=cfg.seed,
            threads=cfg.threads,
            device=cfg.device,
            total_env_steps=cfg.cross_steps,
            out=str(out / "train" / s / cfg.cross_preset),
        )
        ckpt, _ = _train_or_reuse(tcfg, datasets[s], cfg.retrain, say)
        policies[s] = load_policy(ckpt, cfg.device)
        times[s] = policies[s].meta["stats"].get("wall_s")
    say(f"  evaluating {len(scenes)} x {len(scenes)} (train x eval), {cfg.cross_pairs} pairs each")
    m = cross_matrix(policies, datasets, pairs=cfg.cross_pairs, seed=2024)
    for i, s in enumerate(scenes):
        own[s] = {"success": m["success"][i][i], "spl": m["spl"][i][i]}
    pngs = {}
    for key in ("success", "spl"):
        pngs[f"heatmap_{key}"] = plot_matrix(
            m[key],
            scenes,
            scenes,
            figs / f"cross_{group}_{key}.png",
            title=f"{group}: {key} (trained on row, evaluated on column)",
        ).name
    pngs["bars"] = plot_bars(
        m["success"],
        scenes,
        scenes,
        figs / f"cross_{group}_bars.png",
        title=f"{group}: cross-quadrant inference, success over {cfg.cross_pairs} pairs",
    ).name
    return {
        "group": group,
        "scenes": scenes,
        "matrix": m,
        "own": own,
        "train_s": times,
        "png": pngs,
        "preset": cfg.cross_preset,
        "steps": cfg.cross_steps,
        "pairs": cfg.cross_pairs,
    }


__all__ = ["PaperConfig", "Report", "run_paper", "machine_info", "cross_groups", "DEFAULT_SCENES"]
