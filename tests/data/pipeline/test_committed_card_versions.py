"""The versions in the committed cards are the versions a build of today's scene files gives (no ray tracer needed):
a change to a scene file, the RT defaults or the schema that would silently change a dataset fails here."""

import json
from pathlib import Path

import pytest

from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.inputs import build_inputs
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store.versions import version_id

CARDS = Path(__file__).resolve().parents[3] / "cards"
COMMITTED = sorted(p.parent for p in CARDS.glob("*/*/card.json"))


@pytest.mark.parametrize("card_dir", COMMITTED, ids=[f"{p.parent.name}/{p.name}" for p in COMMITTED])
def test_building_a_scene_gives_the_version_of_its_committed_card(card_dir):
    meta = json.loads((card_dir / "card.json").read_text())["meta"]
    spec = load_scene_spec(meta["scene"], meta["variant"])
    cfg = scene_config(BuildConfig(scene=meta["scene"]), spec)  # a city's [rt] defaults, as a build applies them
    inputs = build_inputs(spec, cfg, libraries=meta["library_versions"])
    assert version_id(inputs) == meta["version"]


def test_there_is_a_committed_card_for_each_indoor_twin_and_each_dallas_dataset():
    assert {f"{p.parent.name}/{p.name}" for p in COMMITTED} >= {
        "cubicle/blueprint",
        "cubicle/dynamic",
        "meeting/blueprint",
        "meeting/dynamic",
        "dallas-q1/blueprint",
        "dallas-q2/blueprint",
        "dallas-q3/blueprint",
        "dallas-q4/blueprint",
        "dallas-q3/dynamic",
    }
