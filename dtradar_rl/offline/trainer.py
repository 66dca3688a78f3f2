"""Offline-RL baselines with d3rlpy: log a behaviour policy's transitions on a twin, train on them, evaluate.

    from dtradar_rl.offline.trainer import OfflineConfig, train_offline
    result = train_offline(OfflineConfig(scene="cubicle"))   # --algorithm bcq, the best measured
    result.model      # runs/cubicle/offline/bcq/model.d3, with config.json, losses.csv, results.{json,md} beside it

Three stages, each usable on its own:

1. **Data**: a stored logged dataset (:mod:`dtradar_rl.offline.logged`), named with ``--logged`` or logged (or
   reused, by the logged datasets' own version rules) as ``<scene>/<variant>/<behaviour>`` with this config's
   behaviour, ``transitions`` and ``seed``. Every result names the dataset version it was trained on
   (``config.json`` ``logged``), and opens it as a d3rlpy ``MDPDataset``
   (:func:`dtradar_rl.offline.formats.to_mdp_dataset`).
2. **Training** (:func:`train_offline`): d3rlpy's config → ``create`` → ``fit`` with ``DiscreteCQL``,
   ``DiscreteBCQ``, ``DiscreteBC``, ``DQN``, ``DoubleDQN`` or ``NFQ`` (:data:`ALGORITHMS`), seeded with ``d3rlpy.seed``,
   d3rlpy's own file logging and progress bars off (our ``losses.csv`` holds the per-epoch losses), minibatches drawn
   in one vectorised step (:func:`fast_sampling`, the same batches as d3rlpy's loop, 1.2-2.5x the updates per
   second) and one torch thread (``OfflineConfig.threads``): :func:`fit`, measured by ``bench/bench_offline_speed.py``;
   the weights are those of d3rlpy's defaults for the same seed. d3rlpy's defaults
   are tuned for Atari (learning rate 6.25e-5, target sync every 8000 updates, γ = 0.99); here γ, learning rate,
   target interval and hidden sizes come from :class:`OfflineConfig`, with defaults measured on the cubicle twin.
   With ``--relabel`` the minibatches are the logged steps replayed towards relabelled goals, rewards and terminals
   recomputed from the twin (:mod:`dtradar_rl.offline.relabel`; ``--algorithm bc --relabel future`` is GCBC).
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
import functools
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dtradar_data.core.dataset import Dataset
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_data.store.logged import LoggedDataset
from dtradar_rl.evaluation.evaluate import write_results
from dtradar_rl.evaluation.scored_rows import with_normalized
from dtradar_rl.offline.behaviours import BehaviourConfig
from dtradar_rl.offline.config import ALGORITHMS, OFFLINE_FORMAT, OfflineConfig, check_algorithm
from dtradar_rl.offline.formats import as_logged, import_d3rlpy, quiet_d3rlpy, to_mdp_dataset
from dtradar_rl.offline.log_cache import LogCache, log_content
from dtradar_rl.offline.log_settings import check_compatible
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.offline.memory_senses import MemorySenses
from dtradar_rl.offline.policy import OfflinePolicy, d3rlpy_device, evaluate_offline, load_offline_policy
from dtradar_rl.offline.precision import update_autocast
from dtradar_rl.offline.relabel import RelabelConfig, not_relabellable
from dtradar_rl.offline.relabelled_sampler import relabelled_sampler
from dtradar_rl.offline.relabeller import relabeller
from dtradar_rl.offline.senses import learner_senses
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.observations import Normalizer, build_observations
from dtradar_rl.task.runs import no_empty_folder_on_failure
from dtradar_rl.task.runtime import auto_threads
from dtradar_rl.task.sensing import HONEST_PRESET
from dtradar_rl.task.twins import load_dataset


# -- 2. training ---------------------------------------------------------------------------------------------------
def make_algorithm(cfg: OfflineConfig):
    """The d3rlpy algorithm of ``cfg`` (created, not yet built: ``fit`` builds it from the data)."""
    d3rlpy = import_d3rlpy()
    check_algorithm(cfg.algorithm)
    common = {
        "batch_size": cfg.update_batch_size,
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


def fast_sampling(dataset):
    """``dataset`` (a d3rlpy ``ReplayBuffer``) with a vectorised ``sample_transition_batch``: the same minibatches,
    drawn in one ``np.random.randint(n, size=batch)`` from flat arrays, instead of d3rlpy 2.8.1's Python loop over
    ``batch`` single draws (each picking one ``Transition`` object, then stacking them).

    Identical batches for the same numpy seed (the legacy generator gives the same indices drawn one by one or all at
    once, checked in ``tests/rl/offline/test_ope.py``), so identical weights; measured by
    ``bench/bench_offline_speed.py``: sampling was a third to a half of d3rlpy's update time at batch 256. A
    dataset that is not a plain ``ReplayBuffer`` with the basic transition picker and unbounded buffer is returned
    unchanged. The minibatch's ``transitions`` list is left empty: only returns-to-go read it, which none of
    :data:`ALGORITHMS` (nor FQE) use.
    """
    d3rlpy = import_d3rlpy()
    D = d3rlpy.dataset
    if (
        type(dataset) not in (D.ReplayBuffer, D.MDPDataset)
        or type(dataset.transition_picker) is not D.BasicTransitionPicker
        or type(dataset.buffer) is not D.InfiniteBuffer
    ):
        return dataset
    fast = dataset.__dict__.get("_dtradar_fast")  # built once per dataset (a second on 100 K transitions)
    if fast is None or fast.transition_count != dataset.transition_count:
        fast = _flat_sampler_class()(dataset)
        dataset._dtradar_fast = fast
    return fast


#: the d3rlpy datasets of the most recently opened logged versions in this process (see :func:`mdp_dataset`)
MDP_CACHE_SIZE = 2
_MDP_CACHE: LogCache[Any] = LogCache("d3rlpy dataset", MDP_CACHE_SIZE)


def mdp_dataset(logged: LoggedDataset, senses: MemorySenses | None = None):
    """The d3rlpy dataset of a stored logged version (:func:`~dtradar_rl.offline.formats.to_mdp_dataset`; with
    ``senses``, its observations followed by their memory window), kept for the next runs in this process (the
    :data:`MDP_CACHE_SIZE` most recent): building one from 100 K rows takes seconds, and the benchmark trains (and
    FQE-evaluates) eighteen agents on each. Training never writes to it. One kept of other transitions (or memory
    windows) under the same folder and version is built again, saying so (:mod:`dtradar_rl.offline.log_cache`)."""
    key = (str(logged.path), logged.name, logged.version, type(senses).__name__ if senses is not None else None)
    content = log_content(logged) if senses is None else senses.content
    arrays = None if senses is None else lambda: senses.arrays(logged.arrays())  # built only when not kept
    build = lambda: to_mdp_dataset(logged if arrays is None else arrays())  # noqa: E731
    data = _MDP_CACHE.get(key, content, build, where=f"{logged.name}@{logged.version}")
    data._dtradar_log = log_content(logged)  # a relabelled sampler checks that its parts are of one log
    return data


@functools.cache
def _flat_sampler_class():
    D = import_d3rlpy().dataset

    class FlatTransitionSampler(D.ReplayBuffer):
        """A ``ReplayBuffer`` over the same episodes whose minibatches come from flat arrays (see
        :func:`fast_sampling`)."""

        def __init__(self, source):
            # the source's buffer, episodes and info, shared: building a new ReplayBuffer would draw from numpy's
            # global generator (d3rlpy's writer samples dummy arrays from the signatures) and shift every minibatch
            self.__dict__.update(source.__dict__)
            # what BasicTransitionPicker returns for transition i of each episode, in the buffer's order
            cols: dict[str, list[np.ndarray]] = {k: [] for k in _FLAT_KEYS}
            for ep in self.episodes:
                n, o, a = ep.transition_count, ep.observations, ep.actions
                nxt_o, nxt_a, term = o[1 : n + 1], a[1 : n + 1], np.zeros((n, 1))
                if ep.terminated:  # the last transition ends in a zero observation and action, terminal 1
                    nxt_o = np.concatenate([o[1:n], np.zeros_like(o[:1])])
                    nxt_a = np.concatenate([a[1:n], np.zeros_like(a[:1])])
                    term[-1] = 1.0
                for k, v in zip(_FLAT_KEYS, (o[:n], a[:n], ep.rewards[:n], nxt_o, nxt_a, term)):
                    cols[k].append(v)
            self._flat = {k: np.concatenate(v).astype(np.float32) for k, v in cols.items()}
            if len(self._flat["actions"]) != self.transition_count:  # pragma: no cover - d3rlpy changed its layout
                raise AssertionError("flat transitions do not match the replay buffer")

        def sample_transition_batch(self, batch_size: int):
            i = np.random.randint(self.transition_count, size=batch_size)
            return D.TransitionMiniBatch(
                **{k: v[i] for k, v in self._flat.items()},
                intervals=np.ones((batch_size, 1), np.float32),
                transitions=[],
            )

    return FlatTransitionSampler


_FLAT_KEYS = ("observations", "actions", "rewards", "next_observations", "next_actions", "terminals")


def _epochs(n_steps: int, most: int = 10) -> int:
    """d3rlpy trains ``n_steps // n_steps_per_epoch`` whole epochs (nothing when n_steps < n_steps_per_epoch):
    the most epochs, up to ``most``, that divide ``n_steps`` exactly."""
    return max(k for k in range(1, most + 1) if n_steps % k == 0)


def fit(
    algo,
    data,
    n_steps: int,
    *,
    epochs: int | None = None,
    fast: bool = True,
    on_epoch: Callable[[dict[str, float]], None] | None = None,
    precision: str = "fp32",
    device: str = "cpu",
) -> list[dict[str, float]]:
    """Train ``algo`` ``n_steps`` updates on ``data`` (a d3rlpy dataset); the per-epoch mean losses.

    The settings ``bench/bench_offline_speed.py`` measured fastest, none of which changes a weight: d3rlpy's file
    logger, progress bar, timestamped folder, per-epoch model saves and evaluators off; ``fast``: minibatches from
    :func:`fast_sampling`; ``epochs`` (default :func:`_epochs`: up to 10, a few per run cost nothing measurable)
    only sets how often the losses are averaged. The torch thread count is the caller's; ``precision`` and ``device``
    choose :func:`~dtradar_rl.offline.precision.update_autocast`.
    """
    d3rlpy = import_d3rlpy()
    epochs = epochs or _epochs(n_steps)
    per_epoch = n_steps // epochs
    if fast and not algo.need_returns_to_go:
        data = fast_sampling(data)
    losses: list[dict[str, float]] = []
    with quiet_d3rlpy(), update_autocast(precision, device):
        for epoch, metrics in algo.fitter(
            data,
            n_steps=n_steps,
            n_steps_per_epoch=per_epoch,
            experiment_name=type(algo).__name__,
            with_timestamp=False,
            logger_adapter=d3rlpy.logging.NoopAdapterFactory(),
            show_progress=False,
            save_interval=epochs + 1,
        ):
            row = {
                "epoch": epoch,
                "step": epoch * per_epoch,
                **{k: float(v) for k, v in metrics.items() if not k.startswith("time_")},
            }
            losses.append(row)
            if on_epoch:
                on_epoch(row)
    return losses


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
    #: the d3rlpy dataset of the log as the agent observes it (with ``--senses memory``, the memory window appended;
    #: what FQE evaluates it on)
    data: Any = None


def train_offline(cfg: OfflineConfig, dataset: Dataset | LoggedDataset | str | None = None) -> OfflineResult:
    """Train ``cfg.algorithm`` with d3rlpy on a named logged dataset, save, and evaluate on ``cfg.eval_variants``.

    The logged data is always a stored, versioned dataset: ``dataset`` or ``cfg.logged`` when given (a
    :class:`~dtradar_data.store.logged.LoggedDataset` or its name), checked to have been logged on the twin
    with ``cfg.obs`` (:func:`dtradar_rl.offline.log_settings.check_compatible`); otherwise
    ``<scene>/<variant>/<behaviour>`` logged by :func:`dtradar_rl.offline.logged.log_dataset` with ``cfg``'s
    behaviour, ``transitions`` and ``seed`` (reused when that version is stored). A :class:`Dataset` given as
    ``dataset`` is the twin to log on and evaluate against (default: load ``cfg.dataset_name``).
    """
    cfg = cfg.validate()
    with no_empty_folder_on_failure(cfg.out_dir):  # the folder is made when the model is saved; a failure leaves none
        return _train_offline(cfg, dataset)


def _train_offline(cfg: OfflineConfig, dataset: Dataset | LoggedDataset | str | None) -> OfflineResult:
    """:func:`train_offline` inside its folder guard: data, training, the saved run, evaluation."""
    d3rlpy = import_d3rlpy()
    t_start = time.perf_counter()
    threads = _torch_threads(cfg)
    out = cfg.out_dir
    say = print if cfg.verbose else (lambda *a, **k: None)

    ds, normalizer, store_log = _twin_and_log(cfg, dataset)
    cfg = _auto_senses(cfg, ds, say)
    senses = learner_senses(cfg, store_log, ds)
    logged_data = mdp_dataset(store_log, senses)
    source = {"name": store_log.name, "version": store_log.version, "tag": store_log.tag}
    stats = {**store_log.meta["stats"], "source": f"{store_log.name}@{store_log.version}"}
    say(f"training {cfg.algorithm} on {store_log.name}@{store_log.tag} ({store_log.version})")
    obs_names = _obs_names(cfg, ds, normalizer, senses, logged_data)
    stats["transitions"] = int(logged_data.transition_count)
    relabel, train_data = _training_data(cfg, ds, store_log, logged_data, senses, say)

    d3rlpy.seed(cfg.seed)
    algo = make_algorithm(cfg)
    if algo.need_returns_to_go and train_data is not logged_data:  # pragma: no cover - none of ALGORITHMS does
        raise ConfigError(f"{cfg.algorithm} reads returns-to-go, which relabelled steps do not have")
    losses, train_s = _fit_timed(cfg, algo, train_data, t_start, say)
    if train_data is not logged_data:
        stats["relabel"] = train_data.summary()

    model = _save_model(algo, out)
    meta = {
        "format": OFFLINE_FORMAT,
        "config": cfg.to_dict(),
        "normalizer": normalizer.to_dict(),
        "obs": {
            "preset": HONEST_PRESET if cfg.honest else cfg.obs,
            "sensing": cfg.sensing,
            "senses": cfg.resolved_senses,
            "names": obs_names,
        },
        "dataset": {"name": ds.name, "version": ds.version},
        "logged": source,
        "stats": {"logged": stats, "n_steps": cfg.n_steps, "train_s": train_s, **threads},
        "relabel": stats.get("relabel") or {**relabel.to_dict(), "mix": relabel.describe()},
    }
    write_atomic(out / "config.json", json.dumps(meta, indent=2) + "\n")
    _write_losses(losses, out / "losses.csv")

    policy = load_offline_policy(model, cfg.device)
    rows, md = [], ""
    if cfg.eval_variants:
        rows = evaluate_offline(policy, cfg, datasets={ds.name: ds})
        kw = dict(pairs=cfg.pairs, seed=cfg.eval_seed, max_steps=cfg.max_steps or None, device=cfg.device)
        rows = with_normalized(rows, {ds.name: ds}, **kw)  # the score of the cards and the benchmark, on these pairs
        md = write_results(rows, out, meta)
    wall = time.perf_counter() - t_start
    return OfflineResult(model, out, policy, stats, cfg.n_steps, train_s, wall, losses, rows, md, logged_data)


def _torch_threads(cfg: OfflineConfig) -> dict[str, Any]:
    """Set torch's threads (and flush denormals, whose arithmetic is slow on CPU); the reproducibility record's
    thread count and its setting, and the precision and batch size the updates ran with (``auto`` resolved)."""
    torch.set_num_threads(cfg.threads or auto_threads())
    torch.set_flush_denormal(True)
    numerics = {"precision": cfg.update_precision, "batch_size": cfg.update_batch_size}
    return {"threads": torch.get_num_threads(), "threads_setting": cfg.threads, **numerics}


def _twin_and_log(
    cfg: OfflineConfig, dataset: Dataset | LoggedDataset | str | None
) -> tuple[Dataset, Normalizer, LoggedDataset]:
    """The twin, its feature normaliser and the stored log to train on (named, or logged now), checked to have been
    logged on this twin with this preset and normaliser."""
    ds = dataset if isinstance(dataset, Dataset) else load_dataset(cfg.dataset_name)
    normalizer = Normalizer.fit(ds)
    if isinstance(dataset, (str, LoggedDataset)) or cfg.logged:
        store_log = as_logged(dataset if isinstance(dataset, (str, LoggedDataset)) else cfg.logged)
    else:
        store_log = log_dataset(log_config(cfg), ds)
    check_compatible(store_log, cfg, ds)  # parent twin, its version, preset and normaliser
    return ds, normalizer, store_log


def _auto_senses(cfg: OfflineConfig, ds: Dataset, say) -> OfflineConfig:
    """``cfg`` trained memoryless where ``--senses auto`` would pick the memory a moving twin's log cannot rebuild."""
    if cfg.senses == "auto" and cfg.resolved_senses == "memory" and ds.is_moving:
        say(f"senses: auto does not apply to the moving twin {ds.name} (see --senses memory), training memoryless")
        cfg = dataclasses.replace(cfg, senses="none")
    return cfg


def _obs_names(cfg: OfflineConfig, ds: Dataset, normalizer: Normalizer, senses: MemorySenses | None, data) -> list[str]:
    """The observation's feature names, refused when the log's observations are not as wide: a log made with
    another preset would train an agent that cannot be evaluated."""
    preset = [] if cfg.honest else list(build_observations(ds, cfg.obs, normalizer).names)  # honest: the filter's
    obs_names = preset + list(senses.names if senses else ())
    obs_dim = data.episodes[0].observations.shape[-1]
    if obs_dim != len(obs_names):
        raise ConfigError(
            f"the logged observations have {obs_dim} features, the {cfg.obs!r} preset {len(obs_names)}",
            hint="pass the --obs preset the data was logged with",
        )
    return obs_names


def _training_data(cfg: OfflineConfig, ds: Dataset, store_log: LoggedDataset, logged_data, senses, say):
    """``(relabel, data)``: the relabelling settings and what the minibatches come from (the log itself, or its steps
    replayed towards relabelled goals)."""
    relabel = cfg.relabel_config()
    train_data = logged_data
    why = None
    if cfg.relabel.strip() == "auto" and not relabel.is_identity:
        why = "not built for honest logs" if cfg.honest else not_relabellable(ds, cfg.obs)
    if why:  # the default meets a log it cannot relabel: train on the logged targets, and say so
        say(f"relabelling goals: auto does not apply ({why}), training on the logged targets")
        relabel = RelabelConfig.parse("none", cfg.algorithm, seed=cfg.seed)
    if not relabel.is_identity:  # goals relabelled in every minibatch (or once): dtradar_rl.offline.relabel
        train_data = relabelled_sampler(logged_data, relabeller(store_log, ds), relabel, senses)
        say(f"relabelling goals: {relabel.describe()}, discount {relabel.discount:g}, drawn per {relabel.resample}")
    return relabel, train_data


def _fit_timed(cfg: OfflineConfig, algo, train_data, t_start: float, say) -> tuple[list[dict[str, float]], float]:
    """``(losses, train_s)``: :func:`fit` for ``cfg.n_steps`` updates, each epoch's losses said as they come."""
    epochs = _epochs(cfg.n_steps)

    def progress(row: dict[str, float]) -> None:  # a line per epoch: where, the rate and the time left
        rate = row["step"] / max(time.perf_counter() - t_fit, 1e-9)
        say(
            f"[{time.perf_counter() - t_start:6.1f}s] {cfg.algorithm} epoch {row['epoch']}/{epochs} step "
            f"{row['step']}/{cfg.n_steps}, {rate:.0f} updates/s, {(cfg.n_steps - row['step']) / rate:.0f} s left  "
            + "  ".join(f"{k} {v:.4f}" for k, v in row.items() if k not in ("epoch", "step"))
        )

    t_fit, numerics = time.perf_counter(), {"precision": cfg.update_precision, "device": cfg.device}
    losses = fit(algo, train_data, cfg.n_steps, epochs=epochs, on_epoch=progress, **numerics)
    return losses, time.perf_counter() - t_fit


def _save_model(algo, out: Path) -> Path:
    """Save the algorithm as ``out/model.d3``; its path."""
    model = out / "model.d3"
    tmp_model = out / ".model.d3.tmp"
    out.mkdir(parents=True, exist_ok=True)  # only now is there something to write
    algo.save(str(tmp_model))
    os.replace(tmp_model, model)  # a kill mid-save leaves the previous model, never half of one
    return model


def _write_losses(losses: list[dict[str, float]], path: Path) -> None:
    keys = list(dict.fromkeys(k for row in losses for k in row))
    with open_atomic(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(losses)


__all__ = [
    "ALGORITHMS",
    "OfflineConfig",
    "OfflineResult",
    "fast_sampling",
    "fit",
    "make_algorithm",
    "mdp_dataset",
    "train_offline",
]
