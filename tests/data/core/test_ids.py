"""Dataset id grammar: <scene>/<variant>[@<revision>], with did-you-mean on unknown names, and its second form
for logged datasets, <scene>/<variant>/<behaviour>[@<revision>]."""

import pytest

from dtradar_data.core.errors import UnknownNameError
from dtradar_data.core.ids import (
    DatasetId,
    LoggedId,
    format_id,
    format_logged_id,
    is_logged_name,
    parse_id,
    parse_logged_id,
)
from dtradar_data.store.catalog import as_id, known_scenes

KNOWN = ["cubicle", "meeting", "dallas-q3"]


@pytest.mark.parametrize(
    "text, expected",
    [
        ("cubicle/blueprint", DatasetId("cubicle", "blueprint")),
        ("meeting/dynamic@v12", DatasetId("meeting", "dynamic", "v12")),
        ("dallas-q3/dynamic@0123abc", DatasetId("dallas-q3", "dynamic", "0123abc")),
        ("cubicle/blueprint@0123456789abcdef", DatasetId("cubicle", "blueprint", "0123456789abcdef")),
    ],
)
def test_parse_and_format_are_inverse(text, expected):
    parsed = parse_id(text, known=KNOWN)
    assert parsed == expected
    assert format_id(parsed) == text == str(parsed)


def test_unknown_dataset_name_suggests_the_closest():
    with pytest.raises(UnknownNameError) as err:
        parse_id("cubical/blueprint", known=KNOWN)
    assert "did you mean 'cubicle/blueprint'" in str(err.value)
    assert "cubicle/dynamic" in str(err.value)  # the full list of choices is in the hint


def test_misspelled_variant_suggests_the_right_one():
    with pytest.raises(UnknownNameError, match="did you mean 'meeting/dynamic'"):
        parse_id("meeting/dynamc", known=KNOWN)


def test_a_bare_scene_name_suggests_both_variants():
    with pytest.raises(UnknownNameError, match="'cubicle/blueprint' or 'cubicle/dynamic'"):
        parse_id("cubicle", known=KNOWN)


@pytest.mark.parametrize(
    "bad",
    [
        "cubicle/blueprint@",
        "cubicle/blueprint@latest",
        "cubicle/blueprint@abc",
        "cubicle/blueprint@V1",
        "a/b/c",
        "/blueprint",
        "Cubicle/blueprint",
        "",
    ],
)
def test_malformed_ids_are_rejected_with_the_grammar(bad):
    with pytest.raises(UnknownNameError) as err:
        parse_id(bad, known=KNOWN)
    assert "how to fix" in str(err.value)


def test_grammar_only_parsing_accepts_scenes_that_are_not_known():
    assert parse_id("newscene/dynamic") == DatasetId("newscene", "dynamic")


def test_scenes_stored_in_the_data_root_are_known(tmp_path, monkeypatch):
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path))
    assert "imported" not in known_scenes()
    (tmp_path / "datasets" / "imported" / "blueprint").mkdir(parents=True)
    assert "imported" in known_scenes()
    assert as_id("imported/blueprint").scene == "imported"


@pytest.mark.parametrize(
    "text", ["cubicle/blueprint/noisy-shortest", "cubicle/dynamic/mixture@v3", "dallas-q3/blueprint/random@0123abcd"]
)
def test_logged_ids_are_the_second_form_of_the_same_grammar(text):
    lid = parse_logged_id(text)
    assert isinstance(lid, LoggedId) and format_logged_id(lid) == text == str(lid)
    assert is_logged_name(text) and not is_logged_name(lid.parent) and parse_id(lid.parent).name == lid.parent


@pytest.mark.parametrize(
    "bad",
    [
        "cubicle/blueprint/x@",
        "cubicle/blueprint/x@latest",
        "cubicle/blueprint/x@abc",
        "cubicle/planned/x",
        "cubicle/blueprint/X",
        "cubicle/blueprint",
    ],
)
def test_both_forms_reject_the_same_revisions_and_names(bad):
    with pytest.raises(UnknownNameError):
        parse_logged_id(bad)
