"""Runs repeat: the same seed gives bit-identical weights whatever the thread count and whatever else runs on the
machine, and every run records the threads it used. Kept in the default run so that no later change (thread choice,
data loading, augmentation, noise) breaks it quietly."""

import json
import subprocess
import sys
from contextlib import contextmanager

import pytest
import torch

from dtradar_rl.train.config import DEFAULT_PRESET, config_for
from dtradar_rl.train.dqn import train

BUDGETS = {
    # the default agent (memory, noise augmentation, loop escape): many robots, random pairs
    DEFAULT_PRESET: dict(total_env_steps=2_000, learning_starts=500, hidden=(64, 64)),
    # the paper's agent: one robot, one fixed pair, an update per step (the protocol that flips on another CPU)
    "paper": dict(episodes=6, learning_starts=100),
}


@contextmanager
def busy_core():
    """Another process keeping a core busy while the block runs (as a shared machine does)."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        proc.kill()
        proc.wait()


def _weights(result) -> dict[str, torch.Tensor]:
    return torch.load(result.checkpoint, map_location="cpu", weights_only=False)["q"]


@pytest.mark.parametrize(
    "preset",
    [pytest.param(p, marks=pytest.mark.slow) if p == "paper" else p for p in BUDGETS],  # paper: ~10 s
)
def test_the_same_seed_gives_the_same_weights_on_one_thread_and_on_two_beside_a_busy_process(preset, tmp_path):
    def run(threads, folder):
        cfg = config_for(
            preset,
            scene="synthetic-8x6",
            seed=3,
            threads=threads,
            verbose=False,
            checkpoint_every=0,
            out=str(tmp_path / folder),
            **BUDGETS[preset],
        )
        return train(cfg)

    alone = run(1, "alone")
    with busy_core():
        beside = run(2, "beside")  # two threads, one core taken: the case that slows a run down the most
    a, b = _weights(alone), _weights(beside)
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a), "the same seed trained to different weights"
    assert alone.updates >= 30, "too short a run to compare: no update"
    assert (alone.env_steps, alone.updates, alone.episodes) == (beside.env_steps, beside.updates, beside.episodes)
    assert (tmp_path / "alone" / "curves.csv").read_text() == (tmp_path / "beside" / "curves.csv").read_text()
    runs = {f: json.loads((tmp_path / f / "run.json").read_text()) for f in ("alone", "beside")}
    assert [runs[f]["stats"]["threads"] for f in ("alone", "beside")] == [1, 2]  # the thread count, recorded per run
