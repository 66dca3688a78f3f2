"""Logged (offline-RL) datasets in the store: the name grammar, the transition table's invariants, versions, cards,
load / list / verify and typed errors for damaged or malformed data. numpy and pyarrow only, like the package."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

import dtradar_data
from dtradar_data.core.errors import CorruptDatasetError, DatasetNotFoundError, SchemaMismatchError, UnknownNameError
from dtradar_data.core.files import sha256_file
from dtradar_data.store import logged as T

NAME = "tiny/blueprint/noisy-shortest"


def columns(n_episodes=3, length=4, dim=5, seed=0, last_truncated=True):
    """A valid table's columns: contiguous episodes, next_obs[t] == obs[t+1], one end flag per episode."""
    rng = np.random.default_rng(seed)
    obs, nxt, term, trunc, ep, step = [], [], [], [], [], []
    for e in range(n_episodes):
        o = rng.normal(size=(length + 1, dim)).astype(np.float32)
        obs.append(o[:-1])
        nxt.append(o[1:])
        end_trunc = last_truncated and e == n_episodes - 1
        term.append(np.r_[np.zeros(length - 1, bool), not end_trunc])
        trunc.append(np.r_[np.zeros(length - 1, bool), end_trunc])
        ep.append(np.full(length, e))
        step.append(np.arange(length))
    n = n_episodes * length
    return dict(
        episode=np.concatenate(ep),
        step=np.concatenate(step),
        obs=np.concatenate(obs),
        action=rng.integers(0, 4, n),
        reward=rng.normal(size=n),
        next_obs=np.concatenate(nxt),
        terminated=np.concatenate(term),
        truncated=np.concatenate(trunc),
        robot=np.zeros(n),
        cell=np.arange(n),
        target=np.full(n, 7),
    )


def inputs(seed=0, steps=12):
    return T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="abc",
        behaviour={"kind": "noisy-shortest", "shortest_prob": 0.5},
        steps=steps,
        seed=seed,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": 4},
        libraries={"numpy": "x"},
    )


META = {
    "observations": {"preset": "goal", "names": ["a", "b", "c", "d", "e"]},
    "behaviour_text": "test behaviour",
    "normalizer": {"columns": ["x"], "mean": [0.0], "std": [1.0]},
}


def test_logged_ids_parse_and_format_are_inverse_and_malformed_ones_are_typed_errors():
    for text in (NAME, f"{NAME}@v0", f"{NAME}@0123abcd", "dallas-q3/dynamic/mixture"):
        lid = T.parse_logged_id(text)
        assert T.format_logged_id(lid) == text and T.parse_logged_id(str(lid)) == lid
    assert T.parse_logged_id(NAME).parent == "tiny/blueprint"
    assert T.is_logged_name(NAME) and not T.is_logged_name("cubicle/blueprint@v0")
    for bad in ("tiny/blueprint", "tiny/planned/random", "tiny/blueprint/Random", f"{NAME}@latest", "a/b/c/d"):
        with pytest.raises(UnknownNameError):
            T.parse_logged_id(bad)
    assert T.minari_id(T.parse_logged_id(NAME), "v2") == "dtradar/tiny-blueprint-noisy-shortest-v2"


@pytest.mark.parametrize("damage", ["misaligned", "both_flags", "no_end_flag", "flag_mid_episode", "bad_action"])
def test_a_table_that_breaks_an_episode_invariant_is_a_corrupt_dataset_error(damage):
    c = columns()
    if damage == "misaligned":
        c["next_obs"][1] += 1.0
    elif damage == "both_flags":
        c["truncated"][3] = True
    elif damage == "no_end_flag":
        c["terminated"][3] = False
    elif damage == "flag_mid_episode":
        c["terminated"][1] = True
    else:
        c["action"][0] = 4
    with pytest.raises(CorruptDatasetError):
        T.transitions_table(**c)


def test_a_table_with_another_schema_is_a_schema_mismatch_error():
    table = T.transitions_table(**columns())
    with pytest.raises(SchemaMismatchError, match="missing column 'next_obs'"):
        T.check_transitions(table.drop(["next_obs"]))


def test_a_stored_version_loads_by_name_lists_verifies_and_its_card_says_what_it_holds(root):
    table = T.transitions_table(**columns())
    version, vdir = T.write_logged(NAME, inputs(), table, META)
    ds = dtradar_data.load(NAME)
    assert isinstance(ds, T.LoggedDataset) and (ds.version, ds.tag) == (version, "v0")
    assert ds.frame.shape == (12, len(T.TRANSITION_SCHEMA)) and ds.table.equals(table)
    s = ds.meta["stats"]
    assert (s["episodes"], s["terminated"], s["truncated"], s["cut_by_end_of_log"]) == (3, 2, 1, 0)
    assert s["success_rate"] == pytest.approx(2 / 3)  # 4 steps = the step limit: a failure
    card = (vdir / "README.md").read_text()
    for text in (
        "noisy-shortest",
        "behaviour success rate | 0.667",
        "truncated",
        "not** a terminal",
        "goal",
        "dtradar/tiny-blueprint-noisy-shortest-v0",
        "parent RT dataset | `tiny/blueprint`",
    ):
        assert text in card, text
    assert [e.name for e in T.list_logged()] == [NAME]
    assert T.verify_logged(NAME) == {version: []}


def test_an_episode_cut_by_the_end_of_logging_is_not_counted_as_a_failure():
    s = T.episode_stats(T.transitions_table(**columns()), max_steps=5)
    assert (s["cut_by_end_of_log"], s["success_rate"]) == (1, 1.0)


def test_the_same_name_and_settings_give_the_same_version_and_a_change_a_new_tag(root):
    table = T.transitions_table(**columns())
    v0, _ = T.write_logged(NAME, inputs(), table, META)
    assert T.write_logged(NAME, inputs(), table, META)[0] == v0
    assert T.logged_version(inputs()) == v0
    v1, _ = T.write_logged(NAME, inputs(seed=1), table, META)
    assert v1 != v0
    assert dtradar_data.load(f"{NAME}@v0").version == v0 and dtradar_data.load(NAME).version == v1
    assert dtradar_data.load(f"{NAME}@{v0[:8]}").tag == "v0"


def test_a_changed_or_unreadable_file_is_a_typed_error_and_verify_names_it(root):
    version, vdir = T.write_logged(NAME, inputs(), T.transitions_table(**columns()), META)
    f = vdir / T.TRANSITIONS_FILE
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    with pytest.raises(CorruptDatasetError, match="sha256 differs"):
        dtradar_data.load(NAME)
    assert "sha256 differs" in T.verify_logged(NAME)[version][0]
    # a file with valid hashes but broken content (re-hashed by hand) fails the table check, not silently
    pq.write_table(T.transitions_table(**columns()).drop(["reward"]), f)
    meta = json.loads((vdir / "meta.json").read_text())
    meta["files"][T.TRANSITIONS_FILE]["sha256"] = sha256_file(f)
    (vdir / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(SchemaMismatchError, match="reward"):
        dtradar_data.load(NAME)


def test_a_name_that_was_never_logged_says_how_to_log_it(root):
    with pytest.raises(DatasetNotFoundError, match="dtradar_rl log"):
        dtradar_data.load("tiny/dynamic/random")
