"""Dataset cards: Hub-readable YAML, complete prose, committed cards that fail when stale."""

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from huggingface_hub import DatasetCard

from dtradar_data import cli
from dtradar_data.core.schema import CELL_SCHEMA, COLUMN_DESCRIPTIONS, PATH_SCHEMA
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import cards
from dtradar_data.store import card, writing

REPO_CARDS = Path(__file__).resolve().parents[3] / "cards"
V0, V1 = "0123456789abcdef", "fedcba9876543210"
RT = {
    "frequency_hz": 2.4e9,
    "max_depth": 5,
    "samples_per_src": 100000,
    "seed": 42,
    "los": True,
    "reduction": "strongest path by |a|^2 averaged over port pairs",
}


def put(version=V0, rt=RT, licence="CC-BY-4.0", with_paths=True, png=None):
    ds = synthetic_dataset(6, 4, name="cubicle/blueprint")
    spec = {
        "title": "Cubicle lab",
        "description": "A research lab with cubicles.",
        "licence": licence,
        "source": "hand-modelled",
        "attribution": "dtradar contributors",
        "objects": [{"kind": "chair", "material": "wood"}] * 3 + [{"kind": "wall", "material": "brick"}],
    }
    meta = {
        **ds.meta,
        "scene_spec": spec,
        "rt": rt,
        "licence": licence,
        "attribution": spec["attribution"],
        "library_versions": {"sionna-rt": "2.2.0"},
        "scene_hash": "abc",
        "rx_height_m": 1.0,
    }
    paths = None
    if with_paths:
        n = ds.table.num_rows
        z = pa.array(np.zeros(n, np.float32))
        paths = pa.Table.from_arrays(
            [
                ds.table.column("ix"),
                ds.table.column("iy"),
                pa.array(np.zeros(n, np.int16)),
                z,
                z,
                z,
                z,
                z,
                z,
                z,
                z,
                pa.array(np.zeros(n, np.int8)),
                pa.array([""] * n),
            ],
            schema=PATH_SCHEMA,
        )
    return writing.write_version(
        "cubicle/blueprint",
        version,
        ds.table,
        meta,
        paths=paths,
        extra_files={"coverage.png": png, "cells.png": png} if png else None,
    )


def test_the_card_yaml_parses_and_configs_point_at_files_that_exist(root):
    vdir = put()
    card = DatasetCard.load(vdir / "README.md")
    data = card.data.to_dict()
    assert data["license"] == "cc-by-4.0" and data["size_categories"] == ["n<1K"]
    assert {c["config_name"] for c in data["configs"]} == {"cells", "paths"}
    for config in data["configs"]:
        for entry in config["data_files"]:
            assert (vdir / entry["path"]).is_file(), entry
    assert data["dtradar"] == {
        "name": "cubicle/blueprint",
        "version": V0,
        "tag": "v0",
        "schema_version": 1,
        "hub_repo": "dtradar/dtradar-cubicle-blueprint",
    }


def test_without_a_path_table_the_card_has_no_paths_config(root):
    vdir = put(with_paths=False)
    configs = DatasetCard.load(vdir / "README.md").data.to_dict()["configs"]
    assert [c["config_name"] for c in configs] == ["cells"]


def test_the_card_defines_every_column_every_rt_setting_and_the_angle_convention(root, tmp_path):
    png = tmp_path / "c.png"
    png.write_bytes(b"png")
    text = (put(png=png) / "README.md").read_text()
    for f in list(CELL_SCHEMA) + list(PATH_SCHEMA):
        assert f"| `{f.name}` |" in text
    assert COLUMN_DESCRIPTIONS["aod_zen_rad"] in text
    assert "zenith angles, not elevation" in text and "elevation = π/2 − θ" in text
    for key in RT:
        assert f"| `{key}` |" in text
    assert "## Sionna's radio map" in text and "(coverage.png)" in text and "not the table's values" in text
    assert "## The table, cell by cell" in text and "(cells.png)" in text
    assert text.index("(cells.png)") < text.index("(coverage.png)")  # the table's own picture first
    assert 'dtradar_data.load("cubicle/blueprint@v0")' in text and "load_dataset(" in text
    assert "24 cells: 24 free, 0 blocked" in text
    assert "| v0 | `0123456789abcdef` |" in text and "first version" in text


def test_markdown_tables_survive_pipes_in_descriptions(root):
    text = (put() / "README.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| `path_gain_db` |"))
    assert row.count(" | ") == 3  # four cells: the |a|² in the description is escaped


def test_odbl_geometry_gets_the_openstreetmap_attribution(root):
    text = (put(licence="ODbL-1.0") / "README.md").read_text()
    assert "license: odbl" in text and "© OpenStreetMap contributors" in text and "Open Database License" in text


def test_the_history_records_what_changed_between_versions(root):
    put(V0)
    text = (put(V1, rt={**RT, "max_depth": 6}) / "README.md").read_text()
    assert "| v1 | `fedcba9876543210` |" in text and "`max_depth` 5 → 6" in text


def test_a_snapshot_renders_identically_and_detects_staleness(root, tmp_path):
    put()
    out = tmp_path / "cards"
    target = cards.snapshot("cubicle/blueprint", out)
    assert {p.name for p in target.iterdir()} == {"card.json", "README.md"}
    assert cards.stale_cards(out) == []
    readme = target / "README.md"
    readme.write_text(readme.read_text().replace("zenith", "elevation"))
    assert cards.stale_cards(out) == [target]
    cards.rerender(out)
    assert cards.stale_cards(out) == []
    inputs = json.loads((target / "card.json").read_text())
    inputs["meta"]["rt"]["max_depth"] = 7  # metadata edited without re-rendering
    (target / "card.json").write_text(json.dumps(inputs))
    assert cards.stale_cards(out) == [target]


def test_a_snapshot_carries_the_pictures_its_card_shows(root, tmp_path):
    png = tmp_path / "c.png"
    png.write_bytes(b"png")
    put(png=png)
    target = cards.snapshot("cubicle/blueprint", tmp_path / "cards")
    assert {p.name for p in target.iterdir()} == {"card.json", "README.md", "cells.png", "coverage.png"}
    assert "(cells.png)" in (target / "README.md").read_text()


def test_the_cards_command_refreshes_and_check_fails_on_a_stale_card(root, tmp_path, capsys):
    put()
    out = tmp_path / "cards"
    assert cli.main(["cards", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "wrote" in text and "skipped meeting/blueprint" in text
    assert cli.main(["cards", "--out", str(out), "--check"]) == 0
    (out / "cubicle/blueprint/README.md").write_text("hand edit\n")
    assert cli.main(["cards", "--out", str(out), "--check"]) == 1
    assert "stale" in capsys.readouterr().err


def test_the_committed_cards_of_the_builtin_datasets_are_up_to_date():
    committed = cards.committed_cards(REPO_CARDS)
    assert committed, "cards/<scene>/<variant>/card.json missing: build the datasets and run `make cards`"
    assert cards.stale_cards(REPO_CARDS) == [], "committed cards are stale: run `make cards` and commit cards/"
    for d in committed:
        data = DatasetCard.load(d / "README.md").data.to_dict()
        inputs = json.loads((d / "card.json").read_text())
        assert data["dtradar"]["version"] == inputs["meta"]["version"]
        assert {c["data_files"][0]["path"] for c in data["configs"]} <= set(inputs["meta"]["files"])
        if "coverage.png" in inputs["meta"]["files"]:
            assert (d / "coverage.png").is_file()


@pytest.mark.parametrize("n, label", [(0, "n<1K"), (999, "n<1K"), (1000, "1K<n<10K"), (240_000, "100K<n<1M")])
def test_size_categories_follow_the_hub_buckets(n, label):
    assert card.size_category(n) == label


@pytest.mark.parametrize(
    "text, hub",
    [
        ("ODbL-1.0", "odbl"),
        ("Open Database License", "odbl"),
        ("CC-BY-4.0", "cc-by-4.0"),
        ("proprietary", "other"),
        (None, "other"),
    ],
)
def test_licences_map_to_hub_identifiers(text, hub):
    assert card.license_id(text) == hub
