"""Logged datasets go through the store's list / info / verify / damage paths like RT datasets: a damaged version is
listed as DAMAGED, verify names its file and exits 1, info reads logged names, a mistyped name gets a "did you mean",
each data root keeps its own Minari folder, and the fix a hint gives is the command that logs the version again."""

import json
from pathlib import Path

import numpy as np
import pytest

from dtradar_data import cli
from dtradar_data.core import ids
from dtradar_data.core.errors import CorruptDatasetError, DatasetNotFoundError, UnknownNameError
from dtradar_data.store import listing
from dtradar_data.store import logged as T

NAME = "tiny/blueprint/noisy-shortest"


def columns(n_episodes=3, length=4, dim=5, seed=0):
    """A valid table's columns: contiguous episodes, next_obs[t] == obs[t+1], one end flag per episode."""
    rng = np.random.default_rng(seed)
    parts = {k: [] for k in ("obs", "next_obs", "terminated", "truncated", "episode", "step")}
    for e in range(n_episodes):
        o = rng.normal(size=(length + 1, dim)).astype(np.float32)
        parts["obs"].append(o[:-1])
        parts["next_obs"].append(o[1:])
        last = e == n_episodes - 1
        parts["terminated"].append(np.r_[np.zeros(length - 1, bool), not last])
        parts["truncated"].append(np.r_[np.zeros(length - 1, bool), last])
        parts["episode"].append(np.full(length, e))
        parts["step"].append(np.arange(length))
    n = n_episodes * length
    return {
        **{k: np.concatenate(v) for k, v in parts.items()},
        "action": rng.integers(0, 4, n),
        "reward": rng.normal(size=n),
        "robot": np.zeros(n),
        "cell": np.arange(n),
        "target": np.full(n, 7),
    }


def put(name=NAME, seed=0) -> Path:
    inputs = T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="0123456789abcdef",
        behaviour={"kind": "noisy-shortest", "shortest_prob": 0.5},
        steps=12,
        seed=seed,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": 4},
        libraries={"numpy": "x"},
    )
    meta = {"observations": {"preset": "goal", "names": list("abcde")}, "behaviour_text": "test"}
    return T.write_logged(name, inputs, T.transitions_table(**columns(seed=seed)), meta)[1]


def damage(vdir: Path, how: str) -> str:
    """Damage a stored version; returns the file the damage is in."""
    if how == "missing meta.json":
        (vdir / "meta.json").unlink()
    elif how == "garbage meta.json":
        (vdir / "meta.json").write_text("{not json")
    elif how == "foreign meta.json":
        (vdir / "meta.json").write_text(json.dumps({"record_format": 999}))
    elif how == "missing transitions":
        (vdir / T.TRANSITIONS_FILE).unlink()
        return T.TRANSITIONS_FILE
    else:  # a flipped byte
        f = vdir / T.TRANSITIONS_FILE
        data = bytearray(f.read_bytes())
        data[len(data) // 2] ^= 0xFF
        f.write_bytes(bytes(data))
        return T.TRANSITIONS_FILE
    return "meta.json"


RECORD_DAMAGE = ["missing meta.json", "garbage meta.json", "foreign meta.json"]
ANY_DAMAGE = [*RECORD_DAMAGE, "missing transitions", "flipped byte"]


@pytest.fixture()
def root(root, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MINARI_DATASETS_PATH", raising=False)
    return root


@pytest.mark.parametrize("how", RECORD_DAMAGE)
def test_list_flags_a_logged_version_with_a_missing_or_unreadable_meta_json_as_damaged(root, capsys, how):
    first = put(seed=0)
    put(seed=1)
    damage(first, how)
    assert cli.main(["list"]) == 0
    captured = capsys.readouterr()
    assert f"DAMAGED {NAME}@v0: {first / 'meta.json'}" in captured.out
    assert f"{NAME:<40} v1" in captured.out, "the healthy version is still listed"
    assert "1 damaged version(s)" in captured.err
    assert cli.main(["list", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert [v["tag"] for v in rows[NAME]["versions"]] == ["v1"] and rows[NAME]["kind"] == "logged"
    assert [d["tag"] for d in rows[NAME]["damaged"]] == ["v0"] and "meta.json" in rows[NAME]["damaged"][0]["problem"]
    assert rows[NAME]["latest"] == rows[NAME]["versions"][0]["version"]
    entries = T.list_logged()
    assert [(e.tag, e.problem is None) for e in entries] == [("v0", False), ("v1", True)]


def test_a_logged_dataset_whose_only_version_is_damaged_is_still_listed(root, capsys):
    damage(put(), "missing meta.json")
    assert cli.main(["list"]) == 0
    assert f"DAMAGED {NAME}@v0" in capsys.readouterr().out


@pytest.mark.parametrize("how", ANY_DAMAGE)
@pytest.mark.parametrize("which", ["name", "tag"])
def test_verify_of_a_damaged_logged_version_names_the_file_and_exits_1(root, capsys, how, which):
    vdir = put()
    bad = damage(vdir, how)
    assert cli.main(["verify", NAME if which == "name" else f"{NAME}@v0"]) == 1
    captured = capsys.readouterr()
    assert f"{vdir.name}: FAILED" in captured.out and str(vdir / bad) in captured.out
    assert "not in" not in captured.err
    assert listing.verify(NAME)[vdir.name], "the store's verify takes logged names too"


@pytest.mark.parametrize("how", ANY_DAMAGE)
def test_the_fix_for_a_damaged_logged_version_is_its_log_command_not_make_dataset(root, capsys, how):
    vdir = put()
    damage(vdir, how)
    assert cli.main(["verify", NAME]) == 1
    err = capsys.readouterr().err
    assert "make dataset" not in err
    assert "python -m dtradar_rl log --scene tiny --behaviour noisy-shortest --variant blueprint" in err
    assert "make log SCENE=tiny BEHAVIOUR=noisy-shortest" in err
    if how not in RECORD_DAMAGE:  # the record is readable: every setting of the version, so it logs that version
        assert "--steps 12 --seed 0 --num-envs 1 --obs goal --reward geodesic --max-steps 4" in err
        assert "--revision 0123456789abcdef" in err and "--shortest-prob 0.5" in err
    with pytest.raises(Exception) as e:
        T.load_logged(NAME)
    assert "make dataset" not in (e.value.hint or "") and "dtradar_rl log" in (e.value.hint or "")


def test_a_log_name_that_is_not_the_behaviour_gets_the_name_flag():
    python, make = T.log_commands(T.parse_logged_id("cubicle/dynamic/my-log"), {"behaviour": {"kind": "random"}})
    assert python.startswith("python -m dtradar_rl log --scene cubicle --behaviour random --variant dynamic")
    assert "--name my-log" in python and make.startswith("make log SCENE=cubicle BEHAVIOUR=random ARGS=")


def test_info_takes_a_logged_name_and_says_what_it_holds(root, capsys):
    vdir = put()
    put(seed=1)
    assert cli.main(["info", f"{NAME}@v0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{NAME}@v0  (version {vdir.name}, logged dataset")
    for text in ("parent:      tiny/blueprint @ 0123456789abcdef", "12 in 3 episodes", "transitions.parquet"):
        assert text in out, text
    assert f"dtradar/tiny-blueprint-noisy-shortest-v0 in {root / 'minari'}: not written" in out
    assert f"* v0   {vdir.name}" in out and "  v1 " in out


@pytest.mark.parametrize("how", RECORD_DAMAGE)
def test_info_of_a_damaged_logged_version_names_its_meta_json_with_exit_2(root, capsys, how):
    vdir = put()
    damage(vdir, how)
    assert cli.main(["info", NAME]) == 2
    err = capsys.readouterr().err
    assert str(vdir / "meta.json") in err and "malformed" not in err and "dtradar_rl log" in err


@pytest.mark.parametrize(
    ("typo", "meant"),
    [
        ("tiny/blueprint/noisy-shortst", NAME),
        ("tiny/blueprint/noisy_shortest", NAME),
        ("tyni/blueprint/noisy-shortest", NAME),
        ("tiny/bluprint/noisy-shortest", "blueprint"),
    ],
)
@pytest.mark.parametrize("command", ["info", "verify"])
def test_a_mistyped_logged_name_gets_a_did_you_mean_with_exit_2(root, capsys, typo, meant, command):
    put()
    assert cli.main([command, typo]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and f"did you mean '{meant}'" in err and "Traceback" not in err


def test_a_logged_name_never_stored_says_how_to_log_it_and_suggests_nothing_far(root):
    put()
    with pytest.raises(DatasetNotFoundError) as e:
        T.resolve_logged("tiny/dynamic/random")
    assert "did you mean" not in e.value.message and "python -m dtradar_rl log --scene tiny --behaviour random" in (
        e.value.hint
    )


def test_one_grammar_parses_and_formats_both_forms_and_an_rt_parser_names_the_logged_form():
    for text in ("cubicle/blueprint", "cubicle/dynamic@v2", NAME, f"{NAME}@0123abcd"):
        parsed = ids.parse_name(text)
        assert ids.format_name(parsed) == text and ids.parse_name(parsed) is parsed
    assert isinstance(ids.parse_name("cubicle/blueprint"), ids.DatasetId)
    assert isinstance(ids.parse_name(NAME), ids.LoggedId)
    with pytest.raises(UnknownNameError, match="is a logged dataset id"):
        listing.as_id(NAME)


def test_each_data_root_keeps_its_own_minari_folder_unless_minari_datasets_path_is_set(tmp_path, monkeypatch):
    monkeypatch.delenv("MINARI_DATASETS_PATH", raising=False)
    folders = set()
    for name in ("a", "b"):
        monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / name))
        folders.add(T.minari_root())
        assert T.minari_root() == (tmp_path / name / "minari").absolute()
    assert len(folders) == 2, "two data roots never share one Minari folder by default"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "shared"))
    assert T.minari_root() == (tmp_path / "shared").absolute(), "Minari's own setting wins when it is set"


def test_the_card_says_where_the_minari_copy_is(root):
    card = (put() / "README.md").read_text()
    assert "MINARI_DATASETS_PATH" in card and "<data root>/minari" in card


@pytest.mark.parametrize("how", RECORD_DAMAGE)
def test_loading_a_damaged_logged_version_names_its_file_not_not_stored(root, how):
    vdir = put()
    damage(vdir, how)
    for asked in (NAME, f"{NAME}@v0", f"{NAME}@{vdir.name[:8]}"):
        with pytest.raises(CorruptDatasetError) as e:
            T.load_logged(asked)
        assert str(vdir / "meta.json") in e.value.message and "dtradar_rl log" in e.value.hint
