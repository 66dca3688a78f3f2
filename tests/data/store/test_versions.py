"""Content-addressed versions: identity, reuse, tags, pinned loads of older versions."""

import json

import pytest

from dtradar_data.core.errors import RevisionNotFoundError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import local as store
from dtradar_data.store import versions, writing

SPEC = {"scene": "cubicle", "variant": "blueprint", "objects": [{"kind": "chair", "x_m": 1.0}]}
RT = {"frequency_hz": 2.4e9, "max_depth": 5, "seed": 42}
LIBS = {"sionna-rt": "2.2.0", "mitsuba": "3.9.1"}


def inputs(**changes):
    base = versions.build_inputs(SPEC, RT, 1, LIBS)
    base.update(changes)
    return base


def test_the_same_inputs_give_the_same_version_whatever_the_key_order():
    a = versions.version_id(inputs())
    b = versions.version_id(json.loads(json.dumps(inputs())))  # survives a JSON roundtrip
    reordered = {k: inputs()[k] for k in reversed(list(inputs()))}
    assert a == b == versions.version_id(reordered)
    assert len(a) == 16 and int(a, 16) >= 0


@pytest.mark.parametrize(
    "change",
    [
        {"rt": {**RT, "max_depth": 6}},
        {"rt": {**RT, "seed": 43}},
        {"scene_spec": {**SPEC, "objects": [{"kind": "chair", "x_m": 1.5}]}},
        {"schema_version": 2},
        {"library_versions": {**LIBS, "sionna-rt": "2.3.0"}},
    ],
)
def test_changing_any_input_changes_the_version(change):
    assert versions.version_id(inputs(**change)) != versions.version_id(inputs())


def test_non_finite_inputs_are_refused_rather_than_hashed_ambiguously():
    with pytest.raises(ValueError, match="non-finite"):
        versions.version_id(inputs(rt={**RT, "frequency_hz": float("nan")}))


def test_library_versions_come_from_package_metadata():
    libs = versions.library_versions(("pyarrow", "surely-not-installed-xyz"))
    assert libs["pyarrow"][0].isdigit() and libs["surely-not-installed-xyz"] == "not installed"


def build(rt):
    """What the pipeline does: hash the inputs, reuse or write."""
    ds = synthetic_dataset(5, 4, name="cubicle/blueprint")
    version = versions.version_id(inputs(rt=rt))
    if not store.version_exists("cubicle/blueprint", version):
        writing.write_version("cubicle/blueprint", version, ds.table, {**ds.meta, "rt": rt})
    return version


def test_rebuilding_reuses_a_version_and_a_change_adds_one_both_loadable(root):
    v0 = build(RT)
    assert build(RT) == v0
    v1 = build({**RT, "max_depth": 6})
    assert v1 != v0
    refs = versions.read_refs(root / "datasets/cubicle/blueprint/refs.json")
    assert refs.tags == {"v0": v0, "v1": v1} and refs.latest == v1
    assert store.load("cubicle/blueprint").version == v1
    assert store.load("cubicle/blueprint@v0").version == v0
    assert store.load("cubicle/blueprint", revision=v0[:7]).meta["rt"]["max_depth"] == 5
    assert store.load(f"cubicle/blueprint@{v1}").meta["tag"] == "v1"


def test_rebuilding_an_older_configuration_does_not_change_the_newest(root):
    build(RT)
    v1 = build({**RT, "max_depth": 6})
    build(RT)
    assert store.load("cubicle/blueprint").version == v1


def test_tags_resolve_to_hashes_and_missing_ones_list_what_exists(root):
    v0 = build(RT)
    refs = versions.read_refs(root / "datasets/cubicle/blueprint/refs.json")
    assert versions.resolve_revision(refs, [v0], "v0", "cubicle/blueprint") == v0
    assert versions.resolve_revision(refs, [v0], v0[:7], "cubicle/blueprint") == v0
    with pytest.raises(RevisionNotFoundError) as err:
        versions.resolve_revision(refs, [v0], "v3", "cubicle/blueprint")
    assert f"v0 = {v0}" in str(err.value) and "cubicle/blueprint@v0" in str(err.value)


def test_an_ambiguous_hash_prefix_asks_for_more_characters():
    refs = versions.Refs({"v0": "abcdef0111111111", "v1": "abcdef0222222222"}, "abcdef0222222222")
    with pytest.raises(RevisionNotFoundError, match="several versions"):
        versions.resolve_revision(refs, list(refs.tags.values()), "abcdef0", "x/blueprint")


def test_next_tag_counts_numerically_not_alphabetically():
    refs = versions.Refs({f"v{i}": f"{i:016x}" for i in range(11)})
    assert refs.next_tag() == "v11" and [t for t, _ in refs.ordered()][-2:] == ["v9", "v10"]
