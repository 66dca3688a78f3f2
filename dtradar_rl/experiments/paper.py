"""``make paper``: regenerate the paper's tables and figures from the built datasets into one report folder.

    python -m dtradar_rl paper --scenes cubicle meeting        # -> runs/paper/report.md, report.json, figures/*.png

For every scene: the datasets' sizes (Tables II and V), their coverage maps (Figs. 5 and 7), the paper's agent
trained on the blueprint with the scene's Table VI pair over several seeds (``--seeds``, default 5; training curves,
Figs. 9, 11-16, 18-21; Table VI judged over seeds, see :mod:`.paper_seeds`), the seeds' greedy paths on the blueprint
and dynamic twins (Figs. 10, 22-24); per city, goal-conditioned agents per quadrant (first seed) evaluated on every
quadrant (Fig. 17); and the training time (Table VII). The paper's number stands beside ours
wherever it gives one. Datasets that are not built are named with the command that builds them; the rest goes on.
A trained run whose config is unchanged is reused (``--retrain`` trains again).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.errors import DtradarError, unknown_name
from dtradar_data.core.files import write_atomic
from dtradar_rl.evaluation.evaluate import cross_matrix
from dtradar_rl.experiments.paper_reach import reach_analysis
from dtradar_rl.experiments.paper_report import render
from dtradar_rl.experiments.paper_seeds import SeedJob, auto_workers, read_curves, run_seeds, summarize, train_or_reuse
from dtradar_rl.task.config import Config, ConfigError, check_device, check_unique
from dtradar_rl.task.pairs import ResolvedPair, paper_pair
from dtradar_rl.task.runs import run_dir
from dtradar_rl.task.runtime import machine
from dtradar_rl.task.twins import check_scenes, is_synthetic, load_dataset
from dtradar_rl.train.config import config_for
from dtradar_rl.train.saved_runs import load_policy
from dtradar_rl.viz.figures import plot_bars, plot_seed_curves
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
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    """seeds of the paper's agent: one training run per scene and seed, and the pair counts as reached when at least
    4 of 5 (80 %) of them reproduce it; the goal-conditioned agents of the cross matrix use the first seed only"""
    max_steps: int = 0
    """episode cap of the paper's agent (0 = a safety cap of 10 x the pair's shortest path); the paper's own
    protocol, episodes until the target within its Table VII budget: --max-steps 600000 --total-env-steps 600000"""
    total_env_steps: int = 0
    """environment steps of each run of the paper's agent at most (0 = the preset's 10 M backstop)"""
    jobs: int = 0
    """training runs of the paper's agent at once, each in its own process (0 = one per core)"""
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
    """torch CPU threads of each run (0 = 1 for the paper's agent, which gains nothing from a second one at batch 64;
    auto for the goal-conditioned agents)"""
    device: str = "cpu"
    """torch device"""

    def check_ranges(self) -> None:
        super().check_ranges()
        self.check_at_least(0, "episodes", "threads", "jobs", "max_steps", "total_env_steps")
        self.check_at_least(1, "cross_steps", "cross_pairs")
        if not self.seeds:
            raise ConfigError("--seeds is empty", hint="e.g. --seeds 0 1 2 3 4")
        if any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in self.seeds):
            raise ConfigError(f"--seeds takes non-negative integers, got {list(self.seeds)}")
        check_unique(self.seeds, "seeds")
        check_unique(self.scenes, "scenes")
        check_unique(self.cross_scenes, "cross_scenes")

    def validate(self) -> PaperConfig:
        """Every setting and every scene name, before anything loads or trains: an unknown scene (in --scenes or
        --cross-scenes) is an error with suggestions; a known one that is not built is skipped and named in the
        report with its build command (--cross-scenes must be built: the matrix needs every one)."""
        super().validate()
        if not self.scenes:
            raise ConfigError("--scenes is empty", hint="e.g. --scenes cubicle meeting")
        check_device(self.device)
        config_for(self.cross_preset)  # an unknown preset fails here, before anything trains
        check_scene_names(self.scenes, "scenes")
        if self.cross and self.cross_scenes:
            check_scene_names(self.cross_scenes, "cross_scenes")
            check_scenes(self.cross_scenes, "cross_scenes")
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


def check_scene_names(scenes, option: str) -> None:
    """Each name is a scene this project knows (built in, stored in the data root, or synthetic), else an
    :class:`~dtradar_data.core.errors.UnknownNameError` with suggestions naming ``--<option>``."""
    from dtradar_data.store import known_scenes

    known = set(known_scenes())  # a city is reported by quadrant: "dallas" suggests dallas-q1 ... dallas-q4
    for scene in scenes:
        if not is_synthetic(scene) and scene not in known:
            raise unknown_name(f"scene (--{option.replace('_', '-')})", scene, sorted(known) + ["synthetic-<nx>x<ny>"])


def build_command(scene: str) -> str:
    if scene.startswith("houston"):
        return f"make dataset SCENE={scene}   (downloads OpenStreetMap; offline: OSM=<file>)"
    return f"make dataset SCENE={scene}"


def _size_on_disk(ds: Dataset) -> int | None:
    if ds.path is None:
        return None
    return sum(f.stat().st_size for f in Path(ds.path).iterdir() if f.is_file())


# -- the report --------------------------------------------------------------------------------------------------
def run_paper(cfg: PaperConfig) -> Report:
    """The report of ``cfg``: the built twins (the rest named with their build commands), their sizes and coverage
    maps, the paper's agent over seeds per scene, the cross-quadrant matrices, then ``report.{json,md}``."""
    cfg = cfg.validate()
    say = _Progress()
    out, figs = Path(cfg.out), Path(cfg.out) / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    report = Report(config=asdict(cfg), machine=machine_info())
    twins = _load_twins(cfg, report, say)
    _describe_datasets(twins, report, figs)
    _train_paper_agent(cfg, twins, report, out, figs, say)
    if cfg.cross:
        for group, scenes in cross_groups(cfg, twins):
            say(
                f"cross-quadrant matrix of {group}: goal-conditioned agents ({cfg.cross_preset}, "
                f"{cfg.cross_steps:,} steps each) on {', '.join(scenes)}"
            )
            report.cross.append(_cross(cfg, group, scenes, twins, out, figs, say))
    _write_report(report, out, say)
    return report


def _load_twins(cfg: PaperConfig, report: Report, say) -> dict[str, Dataset]:
    """Every twin of ``--scenes`` that is built, by name; the others go to ``report.missing`` with the command that
    builds them."""
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
    return twins


def _describe_datasets(twins: dict[str, Dataset], report: Report, figs: Path) -> None:
    """Each twin's size (Tables II and V) and coverage map (Figs. 5 and 7) into ``report``; the map is the
    dataset's own where it has one."""
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


def _train_paper_agent(cfg: PaperConfig, twins: dict[str, Dataset], report: Report, out: Path, figs: Path, say) -> None:
    """The paper's agent trained (or reused) on every built blueprint for every seed, then each scene's seeds
    judged against its Table VI pair, with their curves and greedy paths, into ``report``."""
    jobs = [
        SeedJob(
            scene=scene,
            seed=seed,
            out=str(out / "train" / scene / "paper" / f"s{seed}"),
            variants=tuple(v for v in ("blueprint", "dynamic") if f"{scene}/{v}" in twins),
            episodes=cfg.episodes,
            max_steps=cfg.max_steps,
            total_env_steps=cfg.total_env_steps,
            threads=cfg.threads or 1,
            device=cfg.device,
            retrain=cfg.retrain,
        )
        for scene in cfg.scenes
        if f"{scene}/blueprint" in twins
        for seed in cfg.seeds
    ]
    if not jobs:
        return
    workers = cfg.jobs or auto_workers(len(jobs))
    say(
        f"training the paper's agent (Table VI pair): {len(jobs)} run(s) = "
        f"{len(jobs) // len(cfg.seeds)} scene(s) x {len(cfg.seeds)} seed(s), {workers} at once"
    )
    rows = run_seeds(jobs, workers, say)
    for scene in dict.fromkeys(j.scene for j in jobs):
        mine = [r for r in rows if r["scene"] == scene]
        entry = _seed_summary(scene, mine, figs)
        pair = ResolvedPair(**{k: tuple(v) if isinstance(v, list) else v for k, v in mine[0]["pair"].items()})
        entry["reach"] = reach_analysis(twins[f"{scene}/blueprint"], pair)  # how far the protocol is, and why
        for variant in ("blueprint", "dynamic"):
            if variant in mine[0]["greedy"]:
                report.inference.append(_greedy_paths(scene, variant, mine, twins, figs))
        report.training.append(entry)
        say(
            f"  {scene}: {entry['reproduced']} of {entry['n_seeds']} seeds reproduce the pair "
            f"(goal: {entry['needed']}); greedy on the blueprint {entry['greedy_reached'].get('blueprint')}, "
            f"on the dynamic twin {entry['greedy_reached'].get('dynamic', '-')}"
        )


def _seed_summary(scene: str, mine: list[dict[str, Any]], figs: Path) -> dict[str, Any]:
    """The seeds of ``scene`` judged over (Table VI), the paper's row beside them, and their training curves
    drawn (Figs. 9, 11-16, 18-21)."""
    entry = summarize(scene, mine)
    row = paper_pair(scene)
    entry["paper"] = asdict(row) if row else None
    png = figs / f"training_{scene}.png"
    plot_seed_curves(
        {r["seed"]: read_curves(Path(r["run"]) / "curves.csv") for r in mine},
        png,
        shortest=entry["pair"]["shortest"],
        paper_min=row.min_steps if row else None,
        title=f"{scene}/blueprint: the paper's agent over {len(mine)} seed(s), pair "
        f"{tuple(entry['pair']['start'])} -> {tuple(entry['pair']['target'])}",
    )
    entry["png"] = png.name
    return entry


def _greedy_paths(
    scene: str, variant: str, mine: list[dict[str, Any]], twins: dict[str, Dataset], figs: Path
) -> dict[str, Any]:
    """The seeds' greedy paths on one twin of ``scene`` drawn together (Figs. 10, 22-24) and their inference
    entry: how many reach the target, and each seed's run without its path."""
    row = paper_pair(scene)
    g = [r["greedy"][variant] for r in mine]
    hits = sum(x["reached"] for x in g)
    png = figs / f"paths_{scene}_{variant}.png"
    plot_paths(
        twins[f"{scene}/{variant}"],
        [x["path"] for x in g],
        png,
        successes=[x["reached"] for x in g],
        title=f"{scene}/{variant}: the paper's agent, greedy, {hits} of {len(g)} seeds reach the target; "
        f"shortest {g[0]['shortest']}" + (f"; paper: {row.min_steps} (its grid)" if row else ""),
    )
    return {
        "scene": scene,
        "variant": variant,
        "png": png.name,
        "shortest": g[0]["shortest"],
        "start": g[0]["start"],
        "target": g[0]["target"],
        "reached": hits,
        "seeds": [{"seed": r["seed"], **{k: v for k, v in x.items() if k != "path"}} for r, x in zip(mine, g)],
    }


def _write_report(report: Report, out: Path, say) -> None:
    """The wall time and the machine's load over the run into ``report``, then ``report.json`` and ``report.md``."""
    report.wall_s = time.perf_counter() - say.t0
    report.machine["load_avg_max"] = round(max(say.loads + [os.getloadavg()[0]]), 2)
    report.machine["load_avg_end"] = round(os.getloadavg()[0], 2)
    write_atomic(out / "report.json", json.dumps(asdict(report), indent=2, default=str) + "\n")
    write_atomic(out / "report.md", render(report))
    say(f"report: {out / 'report.md'} ({report.wall_s:.0f} s)")


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
            seed=cfg.seeds[0],
            threads=cfg.threads,
            device=cfg.device,
            total_env_steps=cfg.cross_steps,
            out=str(out / "train" / s / cfg.cross_preset),
        )
        ckpt, _ = train_or_reuse(tcfg, datasets[s], cfg.retrain, say)
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
        "seed": cfg.seeds[0],
        "steps": cfg.cross_steps,
        "pairs": cfg.cross_pairs,
    }


__all__ = ["PaperConfig", "Report", "run_paper", "machine_info", "cross_groups", "DEFAULT_SCENES"]
