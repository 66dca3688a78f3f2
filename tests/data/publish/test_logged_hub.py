"""Publish/pull of logged offline-RL datasets: the same protocol as RT datasets, tested offline with a fake Hub."""

import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from huggingface_hub import constants

import dtradar_data
from dtradar_data.core.errors import CorruptDatasetError, HubError
from dtradar_data.publish import logged_hub
from dtradar_data.store import logged as T

NAME = "tiny/blueprint/noisy-shortest"
META = {"observations": {"preset": "goal"}, "behaviour_text": "test", "normalizer": {}}


def columns(n=4, dim=3):
    """One terminated episode of ``n`` steps."""
    rng = np.random.default_rng(0)
    o = rng.normal(size=(n + 1, dim)).astype(np.float32)
    return dict(
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


def inputs():
    return T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="abc",
        behaviour={"kind": "noisy-shortest"},
        steps=4,
        seed=0,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": 4},
        libraries={"numpy": "x"},
    )


@pytest.fixture()
def root(root, tmp_path, monkeypatch):
    for var in ("HF_HUB_OFFLINE", "HF_ENDPOINT", "HF_TOKEN", "HUGGING_FACE_HUB_TOKEN"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setattr(constants, "HF_TOKEN_PATH", str(tmp_path / "no-token"))
    return root


class FakeApi:
    def __init__(self, tags=()):
        self.tags, self.calls = list(tags), []

    def create_repo(self, repo_id, **kw):
        self.calls.append(("create_repo", repo_id))

    def list_repo_refs(self, repo_id, **kw):
        return SimpleNamespace(tags=[SimpleNamespace(name=t) for t in self.tags])

    def create_commit(self, repo_id, ops, **kw):
        self.calls.append(("create_commit", repo_id, ops))
        return SimpleNamespace(oid="c0ffee")

    def create_tag(self, repo_id, tag, revision, **kw):
        self.calls.append(("create_tag", tag, revision))


def published(root, tmp_path):
    version, _ = T.write_logged(NAME, inputs(), T.transitions_table(**columns()), META)
    api = FakeApi()
    result = logged_hub.publish(NAME, api=api)
    served = tmp_path / "served"
    served.mkdir()
    for op in next(c for c in api.calls if c[0] == "create_commit")[2]:
        (served / op.path_in_repo).write_bytes(Path(op.path_or_fileobj).read_bytes())
    return version, api, result, served


def test_publish_sends_the_table_record_and_card_in_one_commit_tagged_twice(root, tmp_path):
    version, api, result, served = published(root, tmp_path)
    assert result.repo_id == "dtradar/dtradar-tiny-blueprint-noisy-shortest" and result.tag == "v0"
    assert sorted(p.name for p in served.iterdir()) == ["README.md", "meta.json", "transitions.parquet"]
    assert [c[1] for c in api.calls if c[0] == "create_tag"] == ["v0", version]


def test_pull_verifies_and_installs_with_the_publishers_tag_and_rejects_a_tampered_copy(root, tmp_path, monkeypatch):
    version, _, _, served = published(root, tmp_path)
    shutil.rmtree(root / "logged")
    monkeypatch.setattr(logged_hub, "_download", lambda repo, rev, dest, cache: Path(shutil.copytree(served, dest)))
    ds = dtradar_data.load(NAME, from_hub=True)
    assert (ds.version, ds.tag) == (version, "v0")
    shutil.rmtree(root / "logged")
    data = bytearray((served / T.TRANSITIONS_FILE).read_bytes())
    data[len(data) // 2] ^= 0xFF
    (served / T.TRANSITIONS_FILE).write_bytes(bytes(data))
    with pytest.raises(CorruptDatasetError, match="failed verification"):
        logged_hub.pull(NAME)
    assert not (root / "logged" / "tiny" / "blueprint" / "noisy-shortest" / version).exists()
    assert list((root / "work").iterdir()) == []


def test_pulling_offline_is_one_clear_hub_error(root, monkeypatch):
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(HubError, match="offline"):
        logged_hub.pull(f"{NAME}@v0", repo_id="me/logged")
