"""Tabular jobs too large for this machine's memory are refused before anything is allocated, naming what each part
needs and what is available; the parts that used to be held twice (the cache's Q*, the greedy table, the uniform
policy's probabilities) are made chunk by chunk. The available memory is faked: nothing large is allocated."""

import tracemalloc

import numpy as np
import pytest

from dtradar_rl.experiments.solve import SolveConfig, solve_scene
from dtradar_rl.tabular import batch, cache, memory, qlearning
from dtradar_rl.tabular.evaluation import policy_values, uniform_values
from dtradar_rl.tabular.memory import TooLargeError
from dtradar_rl.tabular.solver import TabularMDP, solve
from dtradar_rl.task.twins import load_dataset

SCENE = "synthetic-12x8"


@pytest.fixture(scope="module")
def tab():
    return TabularMDP.from_dataset(load_dataset(f"{SCENE}/blueprint"))


@pytest.fixture()
def little_memory(monkeypatch):
    """A machine with 1 MiB available, and no reward table may be computed (no work begins)."""
    monkeypatch.setattr(memory, "available_memory", lambda: 1 << 20)

    def no_work(*a, **k):
        raise AssertionError("work began before the memory was checked")

    monkeypatch.setattr(TabularMDP, "rewards", no_work)


def peak(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_an_exact_solve_or_evaluation_too_large_for_the_available_memory_is_refused_before_any_work(tab, little_memory):
    with pytest.raises(TooLargeError) as e:
        solve(tab, "geodesic", 0.9)
    text = str(e.value)
    assert "needs about" in text and "1.00 MiB" not in text and "0.00 GiB available" in text
    assert "V* (float64" in text and "working arrays" in text and "fewer targets" in e.value.hint
    with pytest.raises(TooLargeError, match="exact evaluation of a table policy"):
        policy_values(tab, np.zeros((tab.n, tab.n), np.int64), tab.cells)
    with pytest.raises(TooLargeError, match="checking its move probabilities"):
        uniform_values(tab, tab.cells)


def test_make_solve_is_refused_up_front_naming_the_twin_and_the_fix(root, tmp_path, little_memory):
    out = tmp_path / "solve"
    with pytest.raises(TooLargeError) as e:
        solve_scene(SolveConfig(scene=SCENE, out=str(out), verbose=False))
    assert f"{SCENE}/blueprint" in e.value.message and "greedy moves" in e.value.message
    assert "--cell-m" in e.value.hint
    assert not out.exists() and not (root / "tabular").exists(), "nothing solved, cached or written"


def test_a_twin_that_fits_the_memory_is_solved_as_before(tab, monkeypatch):
    monkeypatch.setattr(memory, "available_memory", lambda: 64 << 30)
    assert solve(tab, "geodesic", 0.9).values.shape == (tab.n, tab.n)
    monkeypatch.setattr(memory, "available_memory", lambda: None)  # a system that does not say: not checked
    assert solve(tab, "geodesic", 0.9, targets=tab.cells[:3]).values.shape == (3, tab.n)


def test_online_and_batch_learners_too_large_for_the_memory_are_refused_before_the_env_is_made(
    tab, little_memory, monkeypatch
):
    def no_env(*a, **k):
        raise AssertionError("the env was made before the memory was checked")

    monkeypatch.setattr(qlearning, "make_env", no_env)
    ds = load_dataset(f"{SCENE}/blueprint")
    monkeypatch.setattr(memory, "available_memory", lambda: 4096)
    with pytest.raises(TooLargeError, match=r"the Q table \(float32, 96 cells x 96 targets x 4\)") as e:
        qlearning.learn(qlearning.QLearningConfig(scene=SCENE, save=False, verbose=False), ds)
    assert "available" in e.value.message and "--cell-m" in e.value.hint
    model = batch.EmpiricalModel(tab, np.ones((tab.n, 4), np.int64), tab.next.copy(), "geodesic")
    for name in batch.LEARNERS:
        with pytest.raises(TooLargeError, match="learner needs about"):
            batch.learn(name, model, tab.cells)
    pairs = np.stack([tab.cells[:5], tab.cells[-5:]], 1)
    with pytest.raises(TooLargeError, match="the data ceiling"):
        batch.ceiling(model, pairs)


@pytest.mark.slow  # over 3 s: make test-all (CI) runs it
def test_the_cache_and_the_greedy_table_are_made_chunk_by_chunk_never_whole_twice(tmp_path, monkeypatch):
    tab = TabularMDP.from_dataset(load_dataset("synthetic-24x16/blueprint"))  # arrays well above the fixed costs
    monkeypatch.setattr(memory, "CHUNK_BYTES", 2 * tab.n * 32)  # chunks of 2 targets
    sol = solve(tab, "paper", 0.9)
    k, n = sol.targets.size, tab.n
    whole_q = k * n * 4 * 4  # Q* as float32

    assert peak(lambda: cache.save(sol, tmp_path)) < whole_q, "the cache's Q* is never whole in memory"
    q = np.load(tmp_path / "q.npy")
    np.testing.assert_array_equal(q, sol.q().astype(np.float32))
    loaded = cache.load(tmp_path, tab)
    np.testing.assert_array_equal(loaded.values, sol.values)

    greedy = sol.greedy()
    np.testing.assert_array_equal(greedy, sol.q().argmax(-1))
    assert peak(sol.greedy) < 1.5 * greedy.nbytes, "the greedy table is filled in place"

    uniform = uniform_values(tab, sol.targets)
    np.testing.assert_allclose(uniform, policy_values(tab, np.full((k, n, 4), 0.25), sol.targets), rtol=1e-12)
    assert peak(lambda: uniform_values(tab, sol.targets)) < k * n * 4 * 8, "no whole table of 0.25s"
