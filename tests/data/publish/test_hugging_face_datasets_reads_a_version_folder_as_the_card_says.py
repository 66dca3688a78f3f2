"""The card's 🤗 `datasets` snippet: `load_dataset(<repo>, "cells", split="train")` reads the version's Parquet through
the card's `configs`. The Hub serves a repo with exactly the version folder's files, so `datasets` pointed at the
folder itself resolves the card's configs the way it resolves them on the Hub (offline, no network)."""

import pytest

from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import writing

datasets = pytest.importorskip("datasets")  # in [dev]: the test suite checks the snippet the cards show

V0 = "0123456789abcdef"


@pytest.fixture()
def offline_datasets(tmp_path, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_DATASETS_CACHE", str(tmp_path / "hf-cache"))
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", tmp_path / "hf-cache")


def test_the_cells_config_of_a_version_loads_as_the_table(root, offline_datasets):
    ds = synthetic_dataset(6, 4, name="cubicle/blueprint")
    vdir = writing.write_version("cubicle/blueprint", V0, ds.table, {**ds.meta, "rx_height_m": 1.0})
    card = (vdir / "README.md").read_text()
    assert 'load_dataset("dtradar/dtradar-cubicle-blueprint", "cells", split="train", revision="v0")' in card
    cells = datasets.load_dataset(str(vdir), "cells", split="train")
    assert cells.num_rows == ds.table.num_rows
    assert cells.column_names == ds.table.column_names
    assert cells["path_gain_db"] == ds.table.column("path_gain_db").to_pylist()
