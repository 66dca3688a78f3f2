"""A "did you mean" (and the list of choices after it) names only datasets that exist: each built-in scene's real
variants (Sionna's bundled scenes and most city quadrants have no dynamic twin) and what the store holds, never
every variant of every known scene."""

import re

import pytest

import dtradar_data
from dtradar_data import cli
from dtradar_data.core.errors import UnknownNameError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import writing
from dtradar_data.store.catalog import known_names

V0 = "0123456789abcdef"

#: Names no build makes: the scene files give these scenes no such twin.
NEVER = ("sionna-munich/dynamic", "dallas-q1/dynamic", "houston-q1/dynamic", "sionna-munich/moving", "office/moving")


def put(name):
    ds = synthetic_dataset(5, 3, name=name)
    return writing.write_version(name, V0, ds.table, {**ds.meta, "rt": {"max_depth": 5}})


def named(text: str) -> set[str]:
    """Every ``scene/variant`` a message names."""
    return set(re.findall(r"[a-z0-9][a-z0-9_-]*/[a-z]+", text))


def test_a_misspelled_variant_suggests_the_scenes_own_variant(root):
    with pytest.raises(UnknownNameError) as err:
        dtradar_data.load("cubicle/bluepritn")
    assert err.value.message == "unknown dataset 'cubicle/bluepritn'; did you mean 'cubicle/blueprint'?"
    assert err.value.hint == "use one of: cubicle/blueprint, cubicle/dynamic, cubicle/moving"


@pytest.mark.parametrize("typo", ["sionna-munch/dynamic", "dalas-q1/dynamic", "cubical/blueprint", "sionna-munich/x"])
def test_every_name_an_unknown_name_error_gives_exists(root, typo):
    with pytest.raises(UnknownNameError) as err:
        dtradar_data.load(typo)
    text = str(err.value)
    assert named(text) - {typo} <= set(known_names()) and not named(text) & set(NEVER), text
    assert "did you mean" in text or typo == "sionna-munich/x"


def test_a_mistyped_scene_is_offered_a_variant_it_has(root):
    with pytest.raises(UnknownNameError, match="did you mean 'sionna-munich/blueprint'"):
        dtradar_data.load("sionna-munch/dynamic")


def test_the_known_names_are_each_scenes_real_variants(root):
    names = set(known_names())
    assert {"cubicle/blueprint", "cubicle/dynamic", "cubicle/moving", "dallas-q3/dynamic", "dallas-q3/moving"} <= names
    assert {"dallas-q1/blueprint", "sionna-munich/blueprint"} <= names and not names & set(NEVER)


def test_a_stored_scene_is_offered_the_variants_the_store_holds(root):
    put("office/blueprint")  # a user's scene, built from its own file
    with pytest.raises(UnknownNameError) as err:
        dtradar_data.load("office/bluprint")
    assert "did you mean 'office/blueprint'?" in err.value.message and err.value.hint == "use one of: office/blueprint"


def test_the_cli_prints_the_suggestion_among_real_names(root, capsys):
    assert cli.main(["info", "sionna-munich/blueprnt"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown dataset 'sionna-munich/blueprnt'; did you mean 'sionna-munich/blueprint'?")
    assert "how to fix: use one of: sionna-munich/blueprint\n" in err and "dynamic" not in err
