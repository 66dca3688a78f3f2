"""The Python blocks of docs/reference/logged-datasets.md (dtradar_data.load, Minari, d3rlpy) run as written with
each library, on a log of a synthetic twin in place of the cubicle's mixture (the names swapped, the training budget
cut), so the usage the page shows is the libraries' real API."""

import contextlib
import io
import re
from pathlib import Path

import pytest

from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.task.twins import load_dataset

PAGE = Path(__file__).resolve().parents[3] / "docs" / "reference" / "logged-datasets.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", PAGE.read_text(encoding="utf-8"), re.M | re.S)


@pytest.fixture()
def logged(root, tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    cfg = LogConfig(scene="synthetic-10x8", behaviour="noisy-shortest", steps=600, num_envs=6, seed=1, verbose=False)
    return log_dataset(cfg, load_dataset("synthetic-10x8/blueprint"))


def test_the_pages_load_minari_and_d3rlpy_blocks_run_on_a_logged_dataset(logged, tmp_path):
    snippets = [b for b in BLOCKS if "cubicle/blueprint/mixture" in b or "cubicle-blueprint-mixture-v0" in b]
    assert len(snippets) == 3, "the page's dtradar_data, Minari and d3rlpy blocks"
    name = logged.name  # synthetic-10x8/blueprint/noisy-shortest
    minari_id = "dtradar/" + name.replace("/", "-") + "-v0"
    for code in snippets:
        code = code.replace("cubicle/blueprint/mixture", name).replace(
            "dtradar/cubicle-blueprint-mixture-v0", minari_id
        )
        code = code.replace("n_steps=4000, n_steps_per_epoch=1000", "n_steps=20, n_steps_per_epoch=10")
        namespace: dict = {}
        with contextlib.redirect_stdout(io.StringIO()), contextlib.chdir(tmp_path):  # d3rlpy logs into the cwd
            exec(compile(code, str(PAGE), "exec"), namespace)
        if "to_mdp_dataset" in code:
            assert namespace["dataset"].transition_count == len(logged)
        if "minari" in namespace:
            assert namespace["dataset"].total_steps == len(logged)
            features = namespace["episode"].observations.shape[1]  # the last sampled episode
            assert (
                namespace["env"].observation_space.shape == namespace["eval_env"].observation_space.shape == (features,)
            )
