"""Offline-RL baselines with d3rlpy: log a behaviour policy's transitions on a twin, train on them, evaluate.

    from dtradar_rl.offline.trainer import OfflineConfig, train_offline
    result = train_offline(OfflineConfig(scene="cubicle", algorithm="cql"))
    result.model      # runs/cubicle/offline/cql/model.d3, with config.json, losses.csv, results.{json,md} beside it

Three stages, each usable on its own:

1. **Data**: a stored logged dataset (:mod:`dtradar_rl.offline.logged`), named with ``--logged`` or logged (or
   reused, by the logged datasets' own version rules) as ``<scene>/<variant>/<behaviour>`` with this config's
   behaviour, ``transitions`` and ``seed``. Every result names the dataset version it was trained on
   (``config.json`` ``logged``), and opens it as a d3rlpy ``MDPDataset``
   (:func:`dtradar_rl.offline.formats.to_mdp_dataset`).
2. **Training** (:func:`train_offline`): d3rlpy's config → ``create`` → ``fit`` with ``DiscreteCQL``,
   ``DiscreteBCQ``, ``DiscreteBC``, ``DQN``, ``DoubleDQN`` or ``NFQ`` (:data:`ALGORITHMS`), seeded with ``d3rlpy.seed``,
   d3rlpy's own file logging and progress bars off (our ``losses.csv`` holds the per-epoch losses). d3rlpy's defaults
   are tuned for Atari (learning rate 6.25e-5, target sync every 8000 updates, γ = 0.99); here γ, learning rate,
   target interval and hidden sizes come from :class:`OfflineConfig`, with defaults measured on the cubicle twin.
3. **Evaluation**: :class:`~dtradar_rl.offline.policy.OfflinePolicy` wraps the trained algorithm as a
:class:`dtradar_rl.agents.policy.Policy`, so
   :func:`dtradar_rl.evaluation.evaluate.evaluate` runs it unchanged (greedy action = ``algo.predict``). The obstacle
   shield of :meth:`Policy.act <dtradar_rl.agents.policy.Policy.act>` is reused: a vetoed greedy move is replaced by the
   best allowed one by the algorithm's action values (``predict_value``; BC: its policy logits). Blueprint → blueprint
   and blueprint → dynamic go to ``results.json`` / ``results.md`` as for ``make eval``.

``model.d3`` (``algo.save``) and ``config.json`` (this config, the feature normaliser, the observation preset and
the training dataset) make a run reloadable: :func:`dtradar_rl.offline.policy.load_offline_policy`.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.evaluation.evaluate import write_results
from dtradar_rl.offline.behaviours import BehaviourConfig
from dtradar_rl.offline.config import ALGORITHMS, OFFLINE_FORMAT, OfflineConfig, check_algorithm
from dtradar_rl.offline.formats import as_logged, import_d3rlpy, quiet_d3rlpy, to_mdp_dataset
from dtradar_rl.offline.logged import LogConfig, check_compatible, log_dataset
from dtradar_rl.offline.policy import OfflinePolicy, d3rlpy_device, evaluate_offline, load_offline_policy
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.runs import no_empty_folder_on_failure
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.twins import load_dataset


# -- 2. training ---------------------------------------------------------------------------------------------------
def make_algorithm(cfg: OfflineConfig):
    """The d3rlpy algorithm of ``cfg`` (created, not yet built: ``fit`` builds it from the data)."""
    d3rlpy = import_d3rlpy()
    check_algorithm(cfg.algorithm)
    common = {
        "batch_size": cfg.batch_size,
        "learning_rate": cfg.lr,
        "encoder_factory": d3rlpy.models.VectorEncoderFactory(hidden_units=list(cfg.hidden)),
    }
    q_learning = {**common, "gamma": cfg.gamma, "target_update_interval": cfg.target_update_interval}
    algos = d3rlpy.algos
    config = {
        "cql": lambda: algos.DiscreteCQLConfig(**q_learning, alpha=cfg.cql_alpha),
        "bcq": lambda: algos.DiscreteBCQConfig(**q_learning, action_flexibility=cfg.bcq_flexibility, beta=cfg.bc_beta),
        "bc": lambda: algos.DiscreteBCConfig(**common, beta=cfg.bc_beta),
        "dqn": lambda: algos.DQNConfig(**q_learning),
        "ddqn": lambda: algos.DoubleDQNConfig(**q_learning),
        "nfq": lambda: algos.NFQConfig(**common, gamma=cfg.gamma),
    }[cfg.algorithm]()
    return config.create(device=d3rlpy_device(cfg.device))


def _epochs(n_steps: int, most: int = 10) -> int:
    """d3rlpy trains ``n_steps // n_steps_per_epoch`` whole epochs (nothing when n_steps < n_steps_per_epoch):
    the most epochs, up to ``most``, that divide ``n_steps`` exactly."""
    return max(k for k in range(1, most + 1) if n_steps % k == 0)


def log_config(cfg: OfflineConfig) -> LogConfig:
    """The logging settings of ``cfg``: its twin, behaviour, ``transitions`` steps and seed (no Minari copy)."""
    shared = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(BehaviourConfig)}
    return LogConfig(**{**shared, "out": ""}, steps=cfg.transitions, minari=False)


@dataclass
class OfflineResult:
    """What :func:`train_offline` returns."""

    model: Path
    out_dir: Path
    policy: OfflinePolicy
    #: the logged dataset's statistics (steps, episodes, behaviour success rate, ...) and its ``source``:
    #: ``<scene>/<variant>/<name>@<version>``
    logged: dict[str, Any]
    n_steps: int
    train_s: float
    wall_s: float
    losses: list[dict[str, float]] = field(default_factory=list)
    #: evaluation rows (one per twin and shield setting) and their Markdown table
    rows: list[dict[str, Any]] = field(default_factory=list)
    markdown: str = ""


def train_offline(cfg: OfflineConfig, dataset: Dataset | LoggedDataset | str | None = None) -> OfflineResult:
    """Train ``cfg.algorithm`` with d3rlpy on a named logged dataset, save, and evaluate on ``cfg.eval_variants``.

    The logged data is always a stored, versioned dataset: ``dataset`` or ``cfg.logged`` when given (a
    :class:`~dtradar_data.store.logged.LoggedDataset` or its name), checked to have been logged on the twin
    with ``cfg.obs`` (:func:`dtradar_rl.offline.logged.check_compatible`); otherwise
    ``<scene>/<variant>/<behaviour>`` logged by :func:`dtradar_rl.offline.logged.log_dataset` with ``cfg``'s
    behaviour, ``transitions`` and ``seed`` (reused when that version is stored). A :class:`Dataset` given as
    ``dataset`` is the twin to log on and evaluate against (default: load ``cfg.dataset_name``).
    """
    cfg = cfg.validate()
    with no_empty_folder_on_failure(cfg.out_dir):  # the folder is made when the model is saved; a failure leaves none
        return _train_offline(cfg, dataset)


def _train_offline(cfg: OfflineConfig, dataset: Dataset | LoggedDataset | str | None) -> OfflineResult:
    d3rlpy = import_d3rlpy()
    t_start = time.perf_counter()
    torch.set_num_threads(cfg.threads or auto_threads())
    torch.set_flush_denormal(True)
    threads = {"threads": torch.get_num_threads(), "threads_setting": cfg.threads}  # the reproducibility record
    out = cfg.out_dir
    say = print if cfg.verbose else (lambda *a, **k: None)

    ds = dataset if isinstance(dataset, Dataset) else load_dataset(cfg.dataset_name)
    normalizer = Normalizer.fit(ds)
    if isinstance(dataset, (str, LoggedDataset)) or cfg.logged:
        store_log = as_logged(dataset if isinstance(dataset, (str, LoggedDataset)) else cfg.logged)
    else:
        store_log = log_dataset(log_config(cfg), ds)
    check_compatible(store_log, cfg, ds)  # parent twin, its version, preset and normaliser
    logged_data = to_mdp_dataset(store_log)
    source = {"name": store_log.name, "version": store_log.version, "tag": store_log.tag}
    stats = {**store_log.meta["stats"], "source": f"{store_log.name}@{store_log.version}"}
    say(f"training {cfg.algorithm} on {store_log.name}@{store_log.tag} ({store_log.version})")
    obs_names = list(build_observations(ds, cfg.obs, normalizer).names)
    obs_dim = logged_data.episodes[0].observations.shape[-1]
    if obs_dim != len(obs_names):
        raise ConfigError(
            f"the logged observations have {obs_dim} features, the {cfg.obs!r} preset {len(obs_names)}",
            hint="pass the --obs preset the data was logged with",
        )
    stats["transitions"] = int(logged_data.transition_count)

    d3rlpy.seed(cfg.seed)
    algo = make_algorithm(cfg)
    epochs = _epochs(cfg.n_steps)
    losses: list[dict[str, float]] = []
    t_fit = time.perf_counter()
    with quiet_d3rlpy():
        for epoch, metrics in algo.fitter(
            logged_data,
            n_steps=cfg.n_steps,
            n_steps_per_epoch=cfg.n_steps // epochs,
            experiment_name=cfg.algorithm,
            with_timestamp=False,
            logger_adapter=d3rlpy.logging.NoopAdapterFactory(),
            show_progress=False,
            save_interval=epochs + 1,
        ):
            row = {
                "epoch": epoch,
                "step": epoch * (cfg.n_steps // epochs),
                **{k: float(v) for k, v in metrics.items() if not k.startswith("time_")},
            }
            losses.append(row)
            say(
                f"[{time.perf_counter() - t_start:6.1f}s] {cfg.algorithm} epoch {epoch}/{epochs} step {row['step']}  "
                + "  ".join(f"{k} {v:.4f}" for k, v in row.items() if k not in ("epoch", "step"))
            )
    train_s = time.perf_counter() - t_fit

    model = out / "model.d3"
    tmp_model = out / ".model.d3.tmp"
    out.mkdir(parents=True, exist_ok=True)  # only now is there something to write
    algo.save(str(tmp_model))
    os.replace(tmp_model, model)  # a kill mid-save leaves the previous model, never half of one
    meta = {
        "format": OFFLINE_FORMAT,
        "config": cfg.to_dict(),
        "normalizer": normalizer.to_dict(),
        "obs": {"preset": cfg.obs, "names": obs_names},
        "dataset": {"name": ds.name, "version": ds.version},
        "logged": source,
        "stats": {"logged": stats, "n_steps": cfg.n_steps, "train_s": train_s, **threads},
    }
    write_atomic(out / "config.json", json.dumps(meta, indent=2) + "\n")
    _write_losses(losses, out / "losses.csv")

    policy = load_offline_policy(model, cfg.device)
    rows, md = [], ""
    if cfg.eval_variants:
        rows = evaluate_offline(policy, cfg, datasets={ds.name: ds})
        md = write_results(rows, out, meta)
    wall = time.perf_counter() - t_start
    return OfflineResult(model, out, policy, stats, cfg.n_steps, train_s, wall, losses, rows, md)


def _write_losses(losses: list[dict[str, float]], path: Path) -> None:
    keys = list(dict.fromkeys(k for row in losses for k in row))
    with open_atomic(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(losses)


__all__ = ["ALGORITHMS", "OfflineConfig", "OfflineResult", "make_algorithm", "train_offline"]
