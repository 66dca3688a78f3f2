"""docs/reference/logged-datasets.md's 🤗 `datasets` snippet: `load_dataset(<repo>, split="train")` reads
`transitions.parquet` through the card's default config. `datasets` pointed at the version folder (the files the
Hub repo holds) resolves the card's configs as it does on the Hub, offline."""

from pathlib import Path

import pytest

from dtradar_rl.offline.logged import LogConfig, log_dataset
from dtradar_rl.task.twins import load_dataset

datasets = pytest.importorskip("datasets")  # in [dev]: the test suite checks the snippet the docs show


def test_the_default_config_of_a_logged_version_loads_every_transition(root, tmp_path, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", tmp_path / "hf-cache")
    cfg = LogConfig(scene="synthetic-10x8", behaviour="random", steps=600, num_envs=6, minari=False, verbose=False)
    logged = log_dataset(cfg, load_dataset("synthetic-10x8/blueprint"))
    folder = logged.path if logged.path.is_dir() else logged.path.parent
    page = (Path(__file__).resolve().parents[3] / "docs" / "reference" / "logged-datasets.md").read_text()
    snippet = 'load_dataset("dtradar/dtradar-cubicle-blueprint-mixture", split="train", revision="v0")'
    assert f"transitions = {snippet}" in page
    transitions = datasets.load_dataset(str(folder), split="train")
    assert transitions.num_rows == len(logged)
    assert transitions["action"] == logged.frame["action"].to_list()
