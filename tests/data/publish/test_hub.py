"""Hub publish/pull: the network is a few calls; everything around them is tested offline, failures for real."""

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from huggingface_hub import CommitOperationAdd, CommitOperationDelete, constants

import dtradar_data
from dtradar_data.core.errors import CorruptDatasetError, HubError
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import hub
from dtradar_data.store import local as store
from dtradar_data.store import writing

V0, V1 = "0123456789abcdef", "fedcba9876543210"


@pytest.fixture()
def root(root, tmp_path, monkeypatch):
    for var in ("HF_HUB_OFFLINE", "HF_ENDPOINT", "HF_TOKEN", "HUGGING_FACE_HUB_TOKEN", "HF_OIDC_RESOURCE"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", False)
    monkeypatch.setattr(constants, "HF_TOKEN_PATH", str(tmp_path / "no-token"))
    return root


def put(version=V0, scene: Path | None = None, **meta):
    """A stored version; with ``scene`` (a folder), that folder's files as its traced scene (``scene/...``)."""
    ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
    extra = {f"scene/{p.relative_to(scene).as_posix()}": p for p in scene.rglob("*") if p.is_file()} if scene else None
    return writing.write_version(
        "cubicle/blueprint",
        version,
        ds.table,
        {**ds.meta, "rt": {"max_depth": 5}, "licence": "CC-BY-4.0", **meta},
        extra_files=extra,
    )


def a_scene(folder: Path) -> Path:
    """A small Mitsuba scene as a build stores it: ``scene.xml`` naming ``meshes/wood.ply``."""
    (folder / "meshes").mkdir(parents=True)
    (folder / "scene.xml").write_text('<scene version="2.1.0"><!-- meshes/wood.ply --></scene>\n')
    (folder / "meshes" / "wood.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n")
    return folder


def tree(path: Path) -> dict[str, str]:
    """Every file under ``path`` with its content hash: "the store is unchanged" means this is equal."""
    if not path.exists():
        return {}
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


class FakeApi:
    """Records what publish sends; answers like the Hub would for a repo with ``tags`` and ``files``."""

    def __init__(self, tags=(), files=()):
        self.tags, self.files, self.calls = list(tags), list(files), []

    def create_repo(self, repo_id, **kw):
        self.calls.append(("create_repo", repo_id, kw))

    def list_repo_refs(self, repo_id, **kw):
        return SimpleNamespace(tags=[SimpleNamespace(name=t) for t in self.tags])

    def list_repo_files(self, repo_id, **kw):
        return list(self.files)

    def create_commit(self, repo_id, operations, **kw):
        self.calls.append(("create_commit", repo_id, list(operations), kw))
        return SimpleNamespace(oid="c0ffee" * 6 + "c0ff")

    def create_tag(self, repo_id, *, tag, revision, **kw):
        self.calls.append(("create_tag", tag, revision))


def test_publish_sends_one_commit_with_every_file_and_tags_it_twice(root):
    put()
    api = FakeApi(files=["paths.parquet", ".gitattributes"])
    result = hub.publish("cubicle/blueprint", repo_id="me/cubicle-bp", api=api)
    assert (result.tag, result.version, result.commit) == ("v0", V0, "c0ffee" * 6 + "c0ff")
    commits = [c for c in api.calls if c[0] == "create_commit"]
    assert len(commits) == 1
    ops = commits[0][2]
    added = {op.path_in_repo for op in ops if isinstance(op, CommitOperationAdd)}
    assert added == {"cells.parquet", "meta.json", "README.md"}
    # an older version's per-path file would otherwise linger next to this version's cells
    assert [op.path_in_repo for op in ops if isinstance(op, CommitOperationDelete)] == ["paths.parquet"]
    readme = next(op for op in ops if op.path_in_repo == "README.md").path_or_fileobj
    assert b'load_dataset("me/cubicle-bp", "cells"' in readme and b"hub_repo: me/cubicle-bp" in readme
    assert [c[1] for c in api.calls if c[0] == "create_tag"] == ["v0", V0]
    assert commits[0][3]["repo_type"] == "dataset"


def test_publish_sends_the_scene_and_deletes_an_older_versions_meshes(root, tmp_path):
    put(scene=a_scene(tmp_path / "scene"))
    api = FakeApi(files=["scene/scene.xml", "scene/meshes/metal.ply", "paths.parquet"])
    hub.publish("cubicle/blueprint", repo_id="me/cubicle-bp", api=api)
    ops = next(c for c in api.calls if c[0] == "create_commit")[2]
    added = {op.path_in_repo for op in ops if isinstance(op, CommitOperationAdd)}
    assert added == {"cells.parquet", "meta.json", "README.md", "scene/scene.xml", "scene/meshes/wood.ply"}
    deleted = {op.path_in_repo for op in ops if isinstance(op, CommitOperationDelete)}
    assert deleted == {"scene/meshes/metal.ply", "paths.parquet"}
    readme = next(op for op in ops if op.path_in_repo == "README.md").path_or_fileobj
    assert b'sionna.rt.load_scene("scene/scene.xml")' in readme


def test_a_download_asks_for_the_scene_folder(root, monkeypatch, tmp_path):
    asked = []
    monkeypatch.setattr(hub, "download", lambda *a, files: asked.extend(files))
    hub._download("me/bp", "v0", tmp_path / "d", tmp_path / "c")
    assert "scene/*" in asked and "meta.json" in asked


def test_publishing_an_already_published_version_does_nothing(root):
    put()
    api = FakeApi(tags=["v0", V0])
    assert hub.publish("cubicle/blueprint", api=api).already_published
    assert not [c for c in api.calls if c[0] in ("create_commit", "create_tag")]


def test_publishing_refuses_to_move_a_tag_that_names_another_version(root):
    put()
    with pytest.raises(HubError, match="already has a tag 'v0' for another version"):
        hub.publish("cubicle/blueprint", api=FakeApi(tags=["v0", V1]))


def test_a_damaged_version_is_never_published(root):
    vdir = put()
    data = bytearray((vdir / "cells.parquet").read_bytes())
    data[200] ^= 0xFF
    (vdir / "cells.parquet").write_bytes(bytes(data))
    api = FakeApi()
    with pytest.raises(CorruptDatasetError, match="refusing to publish"):
        hub.publish("cubicle/blueprint", api=api)
    assert api.calls == []


def test_publishing_without_a_token_says_how_to_log_in(root):
    put()
    with pytest.raises(HubError, match="no Hugging Face token") as err:
        hub.publish("cubicle/blueprint")
    assert "hf auth login" in str(err.value)


def test_offline_pull_gives_a_clear_error_and_leaves_the_store_unchanged(root, monkeypatch):
    put()
    before = tree(root)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")  # the real snapshot_download runs, local files only
    with pytest.raises(HubError, match="offline mode is on") as err:
        hub.pull("cubicle/blueprint@v3")
    assert "HF_HUB_OFFLINE" in str(err.value)
    assert tree(root) == before and list((root / "work").iterdir()) == []


def test_an_unreachable_hub_gives_a_clear_error_and_leaves_the_store_unchanged(root, monkeypatch):
    put()
    before = tree(root)
    monkeypatch.setenv("HF_ENDPOINT", "http://127.0.0.1:9")  # nothing listens on the discard port
    with pytest.raises(HubError, match=r"could not be reached") as err:
        hub.pull("cubicle/blueprint", revision="v1")
    assert "127.0.0.1:9" in str(err.value)
    assert tree(root) == before and list((root / "work").iterdir()) == []


def test_publishing_to_an_unreachable_hub_with_a_token_gives_a_clear_error(root, monkeypatch):
    put()
    before = tree(root)
    monkeypatch.setenv("HF_TOKEN", "hf_not_a_real_token")
    monkeypatch.setenv("HF_ENDPOINT", "http://127.0.0.1:9")
    with pytest.raises(HubError, match=r"could not be reached") as err:
        hub.publish("cubicle/blueprint")
    assert "127.0.0.1:9" in str(err.value)
    assert tree(root) == before


def test_the_cli_pull_fails_offline_with_one_line_and_status_2(root):
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "dtradar_data", "pull", "meeting/dynamic@v0"],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and proc.stderr.startswith("error: cannot pull") and "Traceback" not in proc.stderr
    assert not (root / "datasets" / "meeting").exists()


@pytest.fixture()
def remote(root, tmp_path, monkeypatch):
    """A published version as a folder, served by replacing the one download call."""
    vdir = put(scene=a_scene(tmp_path / "scene"))  # a version as builds store them now: with its scene
    api = FakeApi()
    hub.publish("cubicle/blueprint", repo_id="me/bp", api=api)
    served = tmp_path / "served"
    served.mkdir()
    for op in next(c for c in api.calls if c[0] == "create_commit")[2]:
        src = op.path_or_fileobj
        (served / op.path_in_repo).parent.mkdir(parents=True, exist_ok=True)
        (served / op.path_in_repo).write_bytes(src if isinstance(src, bytes) else Path(src).read_bytes())
    shutil.rmtree(root)  # a fresh machine: nothing stored locally
    requests = []

    def download(repo_id, revision, dest, cache):
        requests.append((repo_id, revision))
        shutil.copytree(served, dest)
        return dest

    monkeypatch.setattr(hub, "_download", download)
    return SimpleNamespace(dir=served, requests=requests, version_dir=vdir)


def test_pull_verifies_installs_and_keeps_the_publishers_tag(root, remote):
    path = hub.pull("cubicle/blueprint@v0", repo_id="me/bp")
    assert path == root / "datasets/cubicle/blueprint" / V0 and remote.requests == [("me/bp", "v0")]
    ds = store.load("cubicle/blueprint@v0")
    assert ds.version == V0 and ds.table.num_rows == 15
    assert ds.scene_xml.read_bytes() == (remote.dir / "scene/scene.xml").read_bytes(), "the scene came with it"
    assert (path / "scene/meshes/wood.ply").is_file() and store.verify_dir(path) == []
    assert list((root / "work").iterdir()) == []
    assert hub.pull("cubicle/blueprint@v0", repo_id="me/bp") == path and len(remote.requests) == 1  # local now


def test_pull_without_a_revision_takes_main_and_the_tag_from_the_card(root, remote):
    hub.pull("cubicle/blueprint", repo_id="me/bp")
    assert remote.requests == [("me/bp", "main")]
    assert store.load("cubicle/blueprint").meta["tag"] == "v0"


def test_a_tampered_download_is_rejected_and_nothing_is_installed(root, remote):
    data = bytearray((remote.dir / "cells.parquet").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (remote.dir / "cells.parquet").write_bytes(bytes(data))
    with pytest.raises(CorruptDatasetError, match="failed verification"):
        hub.pull("cubicle/blueprint@v0", repo_id="me/bp")
    assert not (root / "datasets/cubicle/blueprint" / V0).exists()
    assert not (root / "datasets/cubicle/blueprint/refs.json").exists()
    assert list((root / "work").iterdir()) == []


def test_a_tampered_scene_file_is_rejected_too(root, remote):
    (remote.dir / "scene/meshes/wood.ply").write_bytes(b"not the mesh")
    with pytest.raises(CorruptDatasetError, match="scene/meshes/wood.ply"):
        hub.pull("cubicle/blueprint@v0", repo_id="me/bp")
    assert not (root / "datasets/cubicle/blueprint" / V0).exists()


def test_load_from_hub_pulls_a_missing_revision(root, remote):
    ds = dtradar_data.load("cubicle/blueprint", revision="v0", from_hub=True, repo_id="me/bp")
    assert ds.version == V0 and remote.requests == [("me/bp", "v0")]
