"""Relabelled minibatches for d3rlpy: :class:`RelabelledSampler`, a ``ReplayBuffer`` over a log's episodes whose
minibatches are its steps replayed towards drawn goals (:mod:`dtradar_rl.offline.relabeller`), so every algorithm
trains on it unchanged. d3rlpy is imported when the class is first asked for.
"""

from __future__ import annotations

import functools
import time
from typing import Any

import numpy as np

from dtradar_data.core.errors import SchemaMismatchError
from dtradar_rl.offline.formats import import_d3rlpy
from dtradar_rl.offline.relabel import FALLBACK, RelabelConfig
from dtradar_rl.offline.relabeller import Relabeller, source_shares


@functools.cache
def _sampler_class():
    D = import_d3rlpy().dataset

    class RelabelledSampler(D.ReplayBuffer):
        """A d3rlpy ``ReplayBuffer`` over a log's episodes whose minibatches are relabelled steps (module
        docstring): indices from numpy's global generator like d3rlpy's (and the trainer's flat sampler), goals from a
        generator of the config's seed."""

        def __init__(self, source, relabeller: Relabeller, cfg: RelabelConfig, senses=None):
            self.__dict__.update(source.__dict__)  # shared, not rebuilt: see the trainer's FlatTransitionSampler
            if self.transition_count != len(relabeller):
                raise SchemaMismatchError(
                    f"the d3rlpy dataset holds {self.transition_count} transitions, the log {len(relabeller)}",
                    hint="relabel the log the d3rlpy dataset was built from",
                )
            _check_one_log(source, relabeller, senses)
            self.relabeller, self.config, self.senses = relabeller, cfg, senses
            self.rng = np.random.default_rng(cfg.seed)
            #: how many drawn goals came from each source (and how many fell back), over every minibatch
            self.counts = np.zeros(FALLBACK + 1, np.int64)
            self.draw_s = 0.0
            self._fixed = None
            if cfg.resample == "run":
                t0 = time.perf_counter()
                idx = np.arange(len(relabeller))
                goal, src = relabeller.goals(idx, cfg, self.rng)
                self._fixed = self._sensed(relabeller.transitions(idx, goal), idx)
                self._fixed_source = src
                self.draw_s = time.perf_counter() - t0

        def sample_transition_batch(self, batch_size: int):
            i = np.random.randint(self.transition_count, size=batch_size)
            if self._fixed is not None:
                batch = {k: v[i] for k, v in self._fixed.items()}
                src = self._fixed_source[i]
            else:
                t0 = time.perf_counter()
                batch, src = self.relabeller.batch(i, self.config, self.rng)
                batch = self._sensed(batch, i)
                self.draw_s += time.perf_counter() - t0
            self.counts += np.bincount(src, minlength=FALLBACK + 1)
            return D.TransitionMiniBatch(**batch, intervals=np.ones((batch_size, 1), np.float32), transitions=[])

        def _sensed(self, batch: dict[str, np.ndarray], idx: np.ndarray) -> dict[str, np.ndarray]:
            """With memory senses, the memory window of rows ``idx`` appended (the same for any goal)."""
            return batch if self.senses is None else self.senses.extend(batch, idx)

        def summary(self) -> dict[str, Any]:
            return {
                **self.config.to_dict(),
                "mix": self.config.describe(),
                "drawn": int(self.counts.sum()),
                "shares": source_shares(self.counts),
                "draw_s": self.draw_s,
                "relabeller_build_s": self.relabeller.build_s,
            }

    return RelabelledSampler


def _check_one_log(source, relabeller: Relabeller, senses) -> None:
    """:class:`SchemaMismatchError` when the d3rlpy dataset, the relabeller and the memory windows were built from
    different transitions (the sha256 each records: :mod:`dtradar_rl.offline.log_cache`). Two logs of one twin with
    as many steps pass the count check, and their minibatches would pair one log's observations with the other's
    relabelled rewards and memory windows; a d3rlpy dataset built elsewhere records none and is checked by count."""
    parts = {
        "the d3rlpy dataset": source.__dict__.get("_dtradar_log"),
        f"the relabeller of {relabeller.name}": relabeller.log,
        "the memory windows": getattr(senses, "log", None),
    }
    known = {what: log for what, log in parts.items() if log}
    if len(set(known.values())) > 1:
        raise SchemaMismatchError(
            "the relabelled minibatches would mix different logs: "
            + ", ".join(f"{what} was built from transitions {log}" for what, log in known.items()),
            hint="build the d3rlpy dataset, the relabeller and the memory windows from one logged version",
        )


def relabelled_sampler(source, relabeller: Relabeller, cfg: RelabelConfig, senses=None):
    """The d3rlpy dataset a trainer fits on: ``source`` (the log's d3rlpy dataset,
    :func:`~dtradar_rl.offline.formats.to_mdp_dataset`) with relabelled minibatches (:class:`RelabelledSampler`);
    with ``senses`` (a :class:`~dtradar_rl.offline.memory_senses.MemorySenses` of the log), each step's memory window
    appended to its observations, as ``source``'s are."""
    return _sampler_class()(source, relabeller, cfg, senses)


def __getattr__(name: str):
    if name == "RelabelledSampler":
        return _sampler_class()
    raise AttributeError(name)


__all__ = ["relabelled_sampler"]
