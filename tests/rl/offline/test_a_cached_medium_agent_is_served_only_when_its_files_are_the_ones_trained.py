"""The medium agent cached on disk (``<root>/logged/<scene>/<variant>/medium/agents/<key>/``) is reused only when its
record is the record of that key and its ``model.pt`` and ``last.pt`` (the replay buffer ``medium-replay`` logs) have
the sha256 the record took; a damaged file, one put back from another run, a record of other inputs or one written
before ``last.pt`` was checked is trained again, saying why. A cache folder written by hand on a tiny synthetic twin,
the training replaced by a stand-in."""

import json

import pytest

from dtradar_data.core.files import sha256_file
from dtradar_data.store import version_id
from dtradar_rl.offline import medium_agent as M
from dtradar_rl.offline.logged import LogConfig
from dtradar_rl.task.twins import load_dataset

CFG = LogConfig(scene="synthetic-8x6", behaviour="medium", num_envs=8, minari=False, verbose=False)


@pytest.fixture()
def cache(root, monkeypatch):
    """``(ds, folder, trained)``: a whole cache folder of CFG's agent, and the list of trainings it led to."""
    ds = load_dataset("synthetic-8x6/blueprint")
    inputs = M.medium_key_inputs(CFG, ds)
    key = version_id(inputs)
    folder = M.medium_agent_dir(CFG, key)
    folder.mkdir(parents=True)
    (folder / "model.pt").write_bytes(b"the agent at the stop")
    (folder / "last.pt").write_bytes(b"its training state and replay buffer")
    record = {
        "key": key,
        "inputs": json.loads(json.dumps(inputs)),
        "stopped_at_env_steps": 2048,
        "score": 55.0,
        "checkpoint_sha256": sha256_file(folder / "model.pt"),
        "last_sha256": sha256_file(folder / "last.pt"),
    }
    (folder / M.MEDIUM_RECORD).write_text(json.dumps(record))
    trained = []
    monkeypatch.setattr(M, "_train_medium", lambda cfg, ds, inputs, key, dest, say: trained.append(key) or "trained")
    return ds, folder, trained


def _record(folder, **changes):
    rec = json.loads((folder / M.MEDIUM_RECORD).read_text())
    rec.update(changes)
    (folder / M.MEDIUM_RECORD).write_text(json.dumps(rec))


def test_a_whole_cache_folder_is_reused(cache):
    ds, folder, trained = cache
    said = []
    agent = M.medium_agent(CFG, ds, say=said.append)
    assert agent.path == folder and trained == [] and "reused" in said[0]


@pytest.mark.parametrize(
    "damage, why",
    [
        (lambda f: (f / "last.pt").write_bytes(b"another run's replay buffer"), "its last.pt is not the one trained"),
        (lambda f: (f / "model.pt").write_bytes(b"a damaged agent"), "its model.pt is not the one trained"),
        (lambda f: (f / "last.pt").unlink(), "its last.pt is missing"),
        (lambda f: _record(f, inputs={"parent": "another/twin"}), "its inputs hash to another key"),
        (lambda f: _record(f, last_sha256=None), "no sha256 of last.pt"),
        (lambda f: (f / M.MEDIUM_RECORD).write_text("{"), "cannot be read"),
    ],
)
def test_a_cache_folder_whose_content_is_not_its_records_is_trained_again_saying_why(cache, damage, why):
    ds, folder, trained = cache
    damage(folder)
    said = []
    assert M.medium_agent(CFG, ds, say=said.append) == "trained"
    assert trained == [folder.name]
    assert len(said) == 1 and why in said[0] and "training it again" in said[0], said
