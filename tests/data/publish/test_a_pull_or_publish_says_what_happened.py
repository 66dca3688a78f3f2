"""A pull says what it did: downloaded (and installed), or nothing downloaded and why (the version asked for is
already here; offline; the Hub unreachable), with the fix for that very dataset: the copy already here or the build
that makes it, its scene filled in. A publish that cannot reach the Hub says so and how to retry. No test needs the
internet: the one download call is replaced by a local folder, the unreachable Hub is the discard port."""

import shutil
from pathlib import Path

import numpy as np
import pytest
from huggingface_hub import constants

from dtradar_data import cli
from dtradar_data.core.errors import HubError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import hub, logged_hub
from dtradar_data.store import logged as T
from dtradar_data.store import writing

V0 = "0123456789abcdef"
NOWHERE = "http://127.0.0.1:9"  # nothing listens on the discard port


@pytest.fixture()
def root(root, tmp_path, monkeypatch):
    for var in ("HF_HUB_OFFLINE", "HF_ENDPOINT", "HF_TOKEN", "HUGGING_FACE_HUB_TOKEN", "HF_OIDC_RESOURCE"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setattr(constants, "HF_TOKEN_PATH", str(tmp_path / "no-token"))
    return root


def put(name="cubicle/blueprint"):
    ds = synthetic_dataset(5, 3, name=name)
    return writing.write_version(name, V0, ds.table, {**ds.meta, "rt": {"max_depth": 5}, "licence": "CC-BY-4.0"})


def test_pulling_a_version_already_here_says_nothing_was_downloaded(root, monkeypatch):
    vdir = put()
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    result = hub.pull_version("cubicle/blueprint@v0")
    assert (result.downloaded, result.installed, result.path, result.version) == (False, False, vdir, V0)
    assert result.describe() == (
        f"nothing downloaded: cubicle/blueprint@v0 is already in the local store ({vdir}), so the Hub was not asked; "
        "`python -m dtradar_data verify cubicle/blueprint@v0` checks it, and a pull downloads it again once that "
        "folder is removed"
    )
    assert hub.pull("cubicle/blueprint", revision=V0) == vdir


def test_a_pull_that_downloads_says_what_it_installed_or_that_it_was_already_here(root, tmp_path, monkeypatch):
    served = Path(shutil.copytree(put(), tmp_path / "served"))
    shutil.rmtree(root / "datasets")  # a fresh machine
    monkeypatch.setattr(hub, "_download", lambda repo, rev, dest, cache: Path(shutil.copytree(served, dest)))
    first = hub.pull_version("cubicle/blueprint@v0")
    assert (
        first.downloaded
        and first.installed
        and first.describe()
        == (f"pulled cubicle/blueprint@v0 (version {V0}) from dtradar/dtradar-cubicle-blueprint into {first.path}")
    )
    again = hub.pull_version("cubicle/blueprint")  # no tag: the Hub's newest, which is the version already here
    assert again.downloaded and not again.installed and again.path == first.path
    assert again.describe().endswith(f"version {V0} was already in the local store ({first.path}); nothing changed")


def test_an_offline_pull_without_a_tag_names_the_copy_already_here(root, monkeypatch, capsys):
    vdir = put()
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(HubError) as err:
        hub.pull("cubicle/blueprint")
    assert (
        "offline mode is on (HF_HUB_OFFLINE=1), so the Hub cannot be asked for its newest version" in err.value.message
    )
    assert err.value.message.endswith("nothing was downloaded")
    assert f"use the copy already here: cubicle/blueprint@v0 ({vdir})" in err.value.hint and "<scene>" not in str(
        err.value
    )
    assert cli.main(["pull", "cubicle/blueprint"]) == 2
    printed = capsys.readouterr().err
    assert "how to fix: unset HF_HUB_OFFLINE" in printed and "cubicle/blueprint@v0" in printed and "<" not in printed


def test_an_offline_pull_of_a_dataset_not_here_names_its_build(root, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(HubError) as err:
        hub.pull("meeting/dynamic@v0")
    assert "and meeting/dynamic@v0 is not in the local store; nothing was downloaded" in err.value.message
    assert "build it locally with `make dataset SCENE=meeting`" in err.value.hint and "<scene>" not in str(err.value)


def test_a_pull_from_an_unreachable_hub_says_how_to_retry_or_build(root, monkeypatch):
    monkeypatch.setenv("HF_ENDPOINT", NOWHERE)
    with pytest.raises(HubError) as err:
        hub.pull("cubicle/moving", revision="v1")
    assert f"the Hub at {NOWHERE} could not be reached" in err.value.message
    assert err.value.message.endswith("nothing was downloaded")
    assert err.value.hint.startswith("check the network and run the same command again, with HF_HUB_OFFLINE unset")
    assert f"HF_ENDPOINT={NOWHERE} is the Hub asked" in err.value.hint
    assert err.value.hint.endswith(
        "or build it locally with `make dataset SCENE=cubicle VARIANT=moving` (or "
        "`python -m dtradar_data build --scene cubicle --variant moving`)"
    )


def test_publishing_to_an_unreachable_hub_says_how_to_retry(root, monkeypatch):
    put()
    monkeypatch.setenv("HF_TOKEN", "hf_not_a_real_token")
    monkeypatch.setenv("HF_ENDPOINT", NOWHERE)
    with pytest.raises(HubError) as err:
        hub.publish("cubicle/blueprint")
    assert f"the Hub at {NOWHERE} could not be reached" in err.value.message
    assert err.value.message.endswith("nothing was uploaded")
    hint = err.value.hint
    assert "run the same command again" in hint and "HF_HUB_OFFLINE unset" in hint and "HF_TOKEN" in hint
    assert "unset HF_ENDPOINT for https://huggingface.co" in hint and "build" not in hint


LOGGED = "tiny/blueprint/random"


def logged():
    n, rng = 3, np.random.default_rng(0)
    o = rng.normal(size=(n + 1, 2)).astype(np.float32)
    table = T.transitions_table(
        episode=np.zeros(n),
        step=np.arange(n),
        obs=o[:-1],
        action=np.zeros(n),
        reward=np.ones(n),
        next_obs=o[1:],
        terminated=np.arange(n) == n - 1,
        truncated=np.zeros(n, bool),
        robot=np.zeros(n),
        cell=np.arange(n),
        target=np.full(n, 9),
    )
    inputs = T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="abc",
        behaviour={"kind": "random"},
        steps=n,
        seed=0,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": n},
        libraries={"numpy": "x"},
    )
    return T.write_logged(LOGGED, inputs, table, {"observations": {"preset": "goal"}, "normalizer": {}})


def test_a_logged_pull_says_the_same(root, monkeypatch):
    version, vdir = logged()
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    result = logged_hub.pull_version(f"{LOGGED}@v0")
    assert not result.downloaded and result.describe().startswith(f"nothing downloaded: {LOGGED}@v0 is already")
    with pytest.raises(HubError) as err:
        logged_hub.pull(LOGGED)
    assert f"use the copy already here: {LOGGED}@v0 ({vdir})" in err.value.hint
