"""A logged dataset's Minari copy carries ``ref_min_score`` / ``ref_max_score``, so ``minari.get_normalized_score``
gives dtradar's return-based normalised score: 0 for uniformly random moves, 100 for the optimum, and any table
policy's exact score in between. Tiny synthetic twins."""

import json

import numpy as np
import pytest

from dtradar_rl.evaluation.evaluate import sample_eval_pairs
from dtradar_rl.evaluation.returns import pair_values, return_references, return_score
from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.tabular.evaluation import policy_values, uniform_values
from dtradar_rl.tabular.solver import GAMMA, TabularMDP, solve
from dtradar_rl.task.twins import load_dataset

minari = pytest.importorskip("minari")

CFG = LogConfig(scene="synthetic-8x6", behaviour="noisy-shortest", steps=240, num_envs=4, seed=1, verbose=False)


@pytest.fixture()
def copy(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    logged = log_dataset(CFG)
    return logged, minari.load_dataset(logged.minari_id)


def test_minaris_normalized_score_is_dtradars_return_score(copy):
    logged, m = copy
    twin = load_dataset("synthetic-8x6/dynamic")  # the copy's evaluation env (recover_environment(eval_env=True))
    assert m.recover_environment(eval_env=True).unwrapped.dataset_name == twin.name
    refs = return_references(twin, reward="geodesic", gamma=GAMMA)
    assert m.storage.metadata["ref_min_score"] == pytest.approx(refs["random"])
    assert m.storage.metadata["ref_max_score"] == pytest.approx(refs["optimal"])
    tab = TabularMDP.from_dataset(twin)
    pairs = sample_eval_pairs(twin, 500, 2024)
    targets = np.unique(pairs[:, 1])
    star = solve(tab, "geodesic", GAMMA, targets)
    j_star = pair_values(tab, star.values, targets, pairs).mean()
    j_rand = pair_values(tab, uniform_values(tab, targets), targets, pairs).mean()
    always_first = policy_values(tab, np.zeros((targets.size, tab.n), np.int64), targets)  # every robot moves X-
    j_first = pair_values(tab, always_first, targets, pairs).mean()
    got = minari.get_normalized_score(m, np.array([j_star, j_rand, j_first]))
    np.testing.assert_allclose(got, [1.0, 0.0, return_score(j_first, refs) / 100], atol=1e-9)


def test_the_copys_record_says_how_its_reference_scores_were_made(copy):
    logged, m = copy
    rec = json.loads((m.storage.data_path.parent / "dtradar.json").read_text())
    assert rec["format"] == 3
    refs = rec["ref_scores"]
    assert refs["twin"].startswith("synthetic-8x6/dynamic") and refs["gamma"] == GAMMA and refs["pairs"] == 500
    assert refs["returns"] == "discounted, from the start" and refs["reward"] == "geodesic"
