"""The offline-RL benchmark: d3rlpy algorithms x logged behaviour datasets x seeds, evaluated with our own rollouts.

    make offline-bench SCENE=cubicle                      # the full setting (long on 2 CPU cores)
    python -m dtradar_rl offline-bench --scene cubicle --seeds 0 --n-steps 2000   # a reduced one

1. The online reference: a DQN checkpoint (``--checkpoint``, else ``runs/<scene>/dqn/model.pt``, else one is trained
   with the ``tuned`` preset and ``--online-steps``) is evaluated on the blueprint and dynamic twins. It is also the
   greedy policy of the ``epsilon-greedy`` behaviour and of the mixture's third component.
2. Every behaviour in ``--behaviours`` logs ``--steps`` steps on the blueprint twin into the store
   (``<scene>/blueprint/<behaviour>``, reused when already logged with the same settings; see
   :mod:`dtradar_rl.offline.logged`). Its own success rate and mean return on those episodes are reported beside the
   algorithms trained on it.
3. Every algorithm in ``--algorithms`` (d3rlpy DiscreteCQL, DiscreteBCQ, DiscreteBC, DQN, DoubleDQN, NFQ) trains
   ``--n-steps`` updates on each dataset for every seed, through :func:`dtradar_rl.offline.trainer.train_offline` (same
   hyper-parameters as ``make offline``), and is evaluated on the same seeded (start, target) pairs of both twins:
   success rate, SPL and collisions per episode, unshielded.
4. ``bench.json`` (every run and the mean ± std over seeds, with the machine's load), ``bench.md`` (the table) and
   ``bench.png`` (bars with the spread over seeds; the online DQN as a line) go to ``--out``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dtradar_data.core.files import write_atomic
from dtradar_data.store.logged import episode_stats
from dtradar_rl.evaluation.evaluate import METRICS, evaluate_twins, metrics_from_rollouts, rollout, sample_eval_pairs
from dtradar_rl.offline.behaviours import BEHAVIOURS, behaviour_policy
from dtradar_rl.offline.config import ALGORITHMS, OfflineConfig, check_algorithm
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.config import Config, ConfigError
from dtradar_rl.task.runs import dqn_checkpoint
from dtradar_rl.task.runtime import describe, machine
from dtradar_rl.task.twins import load_dataset
from dtradar_rl.train.checkpoints import load_policy
from dtradar_rl.train.config import config_for

NAMES = {
    "cql": "DiscreteCQL",
    "bcq": "DiscreteBCQ",
    "bc": "DiscreteBC",
    "dqn": "DQN",
    "ddqn": "DoubleDQN",
    "nfq": "NFQ",
}


@dataclass(frozen=True)
class OfflineBenchConfig(Config):
    """Offline-RL benchmark: d3rlpy algorithms on every logged behaviour dataset of a scene, several seeds,
    evaluated on the blueprint and dynamic twins beside the online DQN and the behaviour itself."""

    scene: str = "cubicle"
    """scene whose blueprint twin is logged on (synthetic-<nx>x<ny> for a stand-in without a ray tracer)"""
    behaviours: tuple[str, ...] = ("random", "noisy-shortest", "epsilon-greedy", "mixture")
    """behaviour datasets to train on"""
    algorithms: tuple[str, ...] = ("cql", "bcq", "bc", "dqn", "ddqn", "nfq")
    """d3rlpy algorithms (cql, bcq, bc, dqn, ddqn, nfq)"""
    seeds: tuple[int, ...] = (0, 1, 2)
    """training seeds of every algorithm (the logged datasets are the same for all: seed 0)"""
    steps: int = 100_000
    """environment steps logged per behaviour"""
    n_steps: int = 10_000
    """d3rlpy updates per run"""
    shortest_prob: float = 0.5
    """noisy-shortest: probability of the shortest-path move"""
    epsilon: float = 0.3
    """epsilon-greedy: probability of a random move"""
    checkpoint: str = ""
    """online DQN checkpoint (default runs/<scene>/dqn/model.pt when it is a memoryless agent, else a tuned one is
    trained into <out>/online_dqn)"""
    online_steps: int = 600_000
    """environment steps of the online DQN when it has to be trained (tuned preset)"""
    num_envs: int = 256
    """robots logging in parallel"""
    pairs: int = 500
    """seeded (start, target) pairs per evaluated twin"""
    variants: tuple[str, ...] = ("blueprint", "dynamic")
    """twins to evaluate on"""
    device: str = "cpu"
    """torch device of logging and training"""
    out: str = ""
    """output folder (default results/offline_bench/<scene>)"""
    verbose: bool = True
    """print progress"""

    @property
    def out_dir(self) -> Path:
        return Path(self.out or f"results/offline_bench/{self.scene}")

    def validate(self) -> OfflineBenchConfig:
        for a in self.algorithms:
            check_algorithm(a)
        for b in self.behaviours:
            if b not in BEHAVIOURS:
                from dtradar_data.core.errors import unknown_name

                raise unknown_name("behaviour policy", b, BEHAVIOURS)
        if not self.seeds or not self.algorithms or not self.behaviours:
            raise ConfigError("--seeds, --algorithms and --behaviours must each list at least one value")
        for name in ("steps", "n_steps", "pairs", "num_envs", "online_steps"):
            if getattr(self, name) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be >= 1")
        return self


def _memoryless(path: Path) -> bool:
    """A checkpoint the epsilon-greedy behaviour can act with (a memory agent's memory is not in a logged step)."""
    return path.is_file() and not getattr(load_policy(path).config, "memory_radius", 0)


def _online_checkpoint(cfg: OfflineBenchConfig, say) -> tuple[Path, dict[str, Any]]:
    path = Path(cfg.checkpoint) if cfg.checkpoint else dqn_checkpoint(cfg.scene)
    if cfg.checkpoint or _memoryless(path):
        return path, {"trained_here": False}
    own = cfg.out_dir / "online_dqn" / "model.pt"  # make train's default agent has a memory: train a tuned one
    if own.is_file():
        return own, {"trained_here": False}
    from dtradar_rl.train.dqn import train

    say(f"no memoryless online DQN at {path}: training one (tuned, {cfg.online_steps} env steps)")
    t0 = time.perf_counter()
    dqn_cfg = replace(
        config_for("tuned", scene=cfg.scene),
        total_env_steps=cfg.online_steps,
        device=cfg.device,
        out=str(cfg.out_dir / "online_dqn"),
        verbose=False,
    )
    result = train(dqn_cfg.validate())
    return result.checkpoint, {"trained_here": True, "train_s": time.perf_counter() - t0, "env_steps": result.env_steps}


def evaluate_behaviour(
    cfg: OfflineBenchConfig, behaviour: str, checkpoint: str | Path | None, twins: dict[str, Any], blueprint: Any
) -> dict[str, dict[str, float]]:
    """The behaviour policy itself, rolled out with our evaluation (same seeded pairs as the trained agents) on
    every twin: ``{variant: {success_rate, spl, collisions}}``."""
    log_cfg = LogConfig(
        scene=cfg.scene,
        behaviour=behaviour,
        shortest_prob=cfg.shortest_prob,
        epsilon=cfg.epsilon,
        checkpoint=str(checkpoint or ""),
    )
    bp = behaviour_policy(log_cfg.spec(), blueprint, obs=log_cfg.obs, seed=2024, device=cfg.device)
    out = {}
    for name, ds in twins.items():
        r = rollout(bp, ds, sample_eval_pairs(ds, cfg.pairs, 2024), device=cfg.device)
        out[name.split("/")[1]] = {m: float(v) for m, v in metrics_from_rollouts(r).to_dict().items() if m in METRICS}
    return out


def _row_metrics(rows: list[dict[str, Any]], variant_name: str) -> dict[str, float]:
    row = next(r for r in rows if r["dataset"] == variant_name and not r.get("shield"))
    return {m: float(row[m]) for m in METRICS}


def aggregate(values: list[float]) -> dict[str, float]:
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=0)), "n": int(len(v))}


def _finish(
    cfg: OfflineBenchConfig,
    online: dict[str, Any],
    datasets: dict[str, Any],
    runs: list[dict[str, Any]],
    m_start: dict[str, Any],
    t_start: float,
) -> dict[str, Any]:
    """Aggregate the runs so far (mean ± std over seeds) and write ``bench.{json,md,png}``."""
    out = cfg.out_dir
    summary = []
    for beh in datasets:
        for algo in cfg.algorithms:
            rs = [r for r in runs if r["behaviour"] == beh and r["algorithm"] == algo]
            if not rs:
                continue
            entry = {
                "behaviour": beh,
                "algorithm": algo,
                "seeds": [r["seed"] for r in rs],
                "train_s": aggregate([r["train_s"] for r in rs]),
            }
            for v in cfg.variants:
                if all(v in r for r in rs):
                    entry[v] = {m: aggregate([r[v][m] for r in rs]) for m in METRICS}
            summary.append(entry)
    result = {
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in cfg.__dict__.items()},
        "algorithms": {a: NAMES[a] for a in cfg.algorithms},
        "online_dqn": online,
        "datasets": datasets,
        "summary": summary,
        "runs": runs,
        "machine": {"start": m_start, "end": machine()},
        "wall_s": time.perf_counter() - t_start,
    }
    write_atomic(out / "bench.json", json.dumps(result, indent=2) + "\n")
    write_atomic(out / "bench.md", markdown(result))
    plot(result, out / "bench.png")
    return result


def run_bench(cfg: OfflineBenchConfig) -> dict[str, Any]:
    """Run the benchmark of ``cfg`` and write ``bench.{json,md,png}``; returns the JSON object."""
    cfg = cfg.validate()
    say = print if cfg.verbose else (lambda *a, **k: None)
    t_start = time.perf_counter()
    out = cfg.out_dir
    out.mkdir(parents=True, exist_ok=True)
    m_start = machine()
    twins = {f"{cfg.scene}/{v}": load_dataset(f"{cfg.scene}/{v}") for v in cfg.variants}
    blueprint = twins.get(f"{cfg.scene}/blueprint") or load_dataset(f"{cfg.scene}/blueprint")
    needs_dqn = any(b in ("epsilon-greedy", "mixture") for b in cfg.behaviours)
    online: dict[str, Any] = {}
    ckpt = Path(cfg.checkpoint) if cfg.checkpoint else None
    if needs_dqn or cfg.checkpoint or _memoryless(dqn_checkpoint(cfg.scene)):
        ckpt, info = _online_checkpoint(cfg, say)
        policy = load_policy(ckpt, cfg.device)
        rows = [
            r
            for r, _, _ in evaluate_twins(
                policy,
                cfg.scene,
                cfg.variants,
                pairs=cfg.pairs,
                seed=2024,
                device=cfg.device,
                shield=False,
                datasets=twins,
            )
        ]
        online = {
            "checkpoint": str(ckpt),
            **info,
            **{r["dataset"].split("/")[1]: {m: float(r[m]) for m in METRICS} for r in rows},
        }
        say(
            f"online DQN {ckpt}: "
            + ", ".join(f"{v} success {online[v]['success_rate']:.3f}" for v in cfg.variants if v in online)
        )

    datasets: dict[str, Any] = {}
    runs: list[dict[str, Any]] = []
    for beh in cfg.behaviours:
        log_cfg = LogConfig(
            scene=cfg.scene,
            behaviour=beh,
            steps=cfg.steps,
            shortest_prob=cfg.shortest_prob,
            epsilon=cfg.epsilon,
            checkpoint=str(ckpt or ""),
            num_envs=cfg.num_envs,
            device=cfg.device,
            minari=False,
            verbose=cfg.verbose,
        )
        t0 = time.perf_counter()
        logged = log_dataset(log_cfg, blueprint)
        # recomputed, not read from the card: logs stored by an older dtradar counted end-of-log cuts as failures
        s = episode_stats(logged.table, (logged.meta.get("settings") or {}).get("max_steps"))
        datasets[beh] = {
            "name": logged.name,
            "version": logged.version,
            "tag": logged.tag,
            "steps": s["steps"],
            "episodes": s["episodes"],
            "cut_by_end_of_log": s["cut_by_end_of_log"],
            "success_rate": s["success_rate"],
            "reached_of_all": s["reached_of_all"],
            "mean_return": s["mean_return"],
            "log_s": time.perf_counter() - t0,
            "eval": evaluate_behaviour(cfg, beh, ckpt, twins, blueprint),
        }
        for algo in cfg.algorithms:
            for seed in cfg.seeds:
                ocfg = OfflineConfig(
                    scene=cfg.scene,
                    algorithm=algo,
                    seed=seed,
                    n_steps=cfg.n_steps,
                    pairs=cfg.pairs,
                    eval_variants=tuple(cfg.variants),
                    shield=False,
                    device=cfg.device,
                    num_envs=cfg.num_envs,
                    verbose=False,
                    out=str(out / "runs" / beh / algo / f"seed{seed}"),
                )
                r = train_offline(ocfg, dataset=logged)
                run = {
                    "behaviour": beh,
                    "algorithm": algo,
                    "seed": seed,
                    "train_s": r.train_s,
                    "wall_s": r.wall_s,
                    **{
                        v: _row_metrics(r.rows, f"{cfg.scene}/{v}")
                        for v in cfg.variants
                        if any(x["dataset"] == f"{cfg.scene}/{v}" for x in r.rows)
                    },
                }
                runs.append(run)
                say(
                    f"[{time.perf_counter() - t_start:7.1f}s] {beh:<15} {NAMES[algo]:<12} seed {seed}: "
                    + ", ".join(f"{v} {run[v]['success_rate']:.3f}" for v in cfg.variants if v in run)
                    + f" ({r.train_s:.1f} s training)"
                )
        _finish(cfg, online, datasets, runs, m_start, t_start)  # partial results survive an interrupted run

    result = _finish(cfg, online, datasets, runs, m_start, t_start)
    say(markdown(result), end="")
    say(f"results: {out / 'bench.json'}, {out / 'bench.md'}, {out / 'bench.png'}")
    return result


def _pm(a: dict[str, float] | None, fmt: str = "{:.3f}") -> str:
    if not a:
        return "-"
    return fmt.format(a["mean"]) + (" ± " + fmt.format(a["std"]) if a["n"] > 1 else "")


def markdown(result: dict[str, Any]) -> str:
    """The benchmark table: one row per behaviour dataset, then one per algorithm trained on it (mean ± std)."""
    cfg = result["config"]
    variants = cfg["variants"]
    head = (
        "| dataset | policy | "
        + " | ".join(f"{v}: success | {v}: SPL | {v}: collisions/ep" for v in variants)
        + " | train (s) |"
    )
    lines = [
        f"Offline RL on `{cfg['scene']}` ({len(cfg['seeds'])} seed(s): {', '.join(map(str, cfg['seeds']))}; "
        f"{cfg['n_steps']} d3rlpy updates; {cfg['steps']} logged steps per behaviour; {cfg['pairs']} seeded "
        "pairs per twin, unshielded; mean ± std over seeds)",
        "",
        head,
        "|" + "---|" * (3 + 3 * len(variants)),
    ]
    online = result.get("online_dqn") or {}
    if online:
        cells = []
        for v in variants:
            m = online.get(v) or {}
            cells += [f"{m.get(k, float('nan')):.3f}" if m else "-" for k in ("success_rate", "spl")]
            cells += [f"{m['collisions']:.2f}" if m else "-"]
        lines.append("| (online) | DQN, tuned | " + " | ".join(cells) + " | - |")
    for beh, d in result["datasets"].items():
        ev = d.get("eval") or {}
        blank = " | ".join(
            f"{ev[v]['success_rate']:.3f} | {ev[v]['spl']:.3f} | {ev[v]['collisions']:.2f}" if v in ev else "- | - | -"
            for v in variants
        )
        lines.append(
            f"| `{d['name']}`@{d['tag']} | behaviour itself (its logged episodes on the blueprint: success "
            f"{d['success_rate']:.3f} of finished episodes, {d.get('reached_of_all', 0):.3f} of all; "
            f"mean return {d['mean_return']:.2f}, {d['episodes']} episodes, "
            f"{d.get('cut_by_end_of_log', 0)} cut by the end of logging) | "
            f"{blank} | - |"
        )
        for e in (e for e in result["summary"] if e["behaviour"] == beh):
            cells = []
            for v in variants:
                m = e.get(v) or {}
                cells += [_pm(m.get("success_rate")), _pm(m.get("spl")), _pm(m.get("collisions"), "{:.2f}")]
            lines.append(
                f"| {beh} | {result['algorithms'][e['algorithm']]} | "
                + " | ".join(cells)
                + f" | {e['train_s']['mean']:.1f} |"
            )
    mach = result["machine"]
    lines += [
        "",
        f"Machine: {describe(mach['start'])}; load average (1/5/15 min) at start "
        f"{_load(mach['start'])}, at end {_load(mach['end'])}; total wall time {result['wall_s']:.0f} s.",
    ]
    return "\n".join(lines) + "\n"


def _load(m: dict[str, Any]) -> str:
    la = m.get("load_average")
    return "/".join(f"{x:.1f}" for x in la) if la else "-"


def plot(result: dict[str, Any], path: Path) -> Path:
    """Success bars per dataset and algorithm, one panel per twin, error bars = std over seeds; online DQN dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = result["config"]["variants"]
    behs = list(result["datasets"])
    algos = list(result["algorithms"])
    fig, axes = plt.subplots(1, len(variants), figsize=(5.5 * len(variants), 4.2), squeeze=False)
    width = 0.8 / max(1, len(algos))
    for ax, v in zip(axes[0], variants):
        x = np.arange(len(behs))
        for k, a in enumerate(algos):
            means, stds = [], []
            for b in behs:
                e = next((e for e in result["summary"] if e["behaviour"] == b and e["algorithm"] == a), {})
                m = (e.get(v) or {}).get("success_rate") or {"mean": np.nan, "std": 0.0}
                means.append(m["mean"])
                stds.append(m["std"])
            ax.bar(
                x + (k - (len(algos) - 1) / 2) * width,
                means,
                width,
                yerr=stds,
                capsize=2,
                label=result["algorithms"][a],
            )
        beh_success = [
            ((result["datasets"][b].get("eval") or {}).get(v) or {}).get("success_rate", np.nan) for b in behs
        ]
        ax.scatter(x, beh_success, marker="x", color="k", zorder=3, label="behaviour itself")
        online = (result.get("online_dqn") or {}).get(v)
        if online:
            ax.axhline(online["success_rate"], color="k", ls="--", lw=1, label="online DQN")
        ax.set_xticks(x, behs, rotation=15)
        ax.set_ylim(0, 1.25)
        ax.set_ylabel("success rate")
        ax.set_title(f"{result['config']['scene']} → {v}")
    axes[0][-1].legend(fontsize=7, loc="upper right", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


__all__ = ["ALGORITHMS", "OfflineBenchConfig", "aggregate", "markdown", "plot", "run_bench"]
