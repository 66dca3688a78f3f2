"""``verify`` on a read-only data root (a shared mirror, a container image): it checks the files and says "ok" with exit
status 0, a damaged version "FAILED" with 1; looking for live writers (whose locks sit under ``<root>/work``) needs no
write access. Skipped where chmod does not stop writes (as root)."""

import numpy as np

from dtradar_data.cli import main
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import logged as T
from dtradar_data.store import writing

V0 = "0123456789abcdef"
LOGGED = "tiny/blueprint/noisy-shortest"


def verify(capsys, *args):
    code = main(["verify", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_verify_of_a_read_only_data_root_says_ok_with_exit_status_0(root, read_only, capsys):
    ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
    writing.write_version("cubicle/blueprint", V0, ds.table, {**ds.meta, "rt": {}})
    read_only()
    for name in ("cubicle/blueprint", f"cubicle/blueprint@{V0[:12]}"):
        code, out, err = verify(capsys, name)
        assert (code, out.strip(), err) == (0, f"{V0}: ok", ""), out + err


def test_a_damaged_version_on_a_read_only_data_root_is_reported_failed(root, read_only, capsys):
    ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
    vdir = writing.write_version("cubicle/blueprint", V0, ds.table, {**ds.meta, "rt": {}})
    (vdir / "cells.parquet").write_bytes(b"not parquet")
    read_only()
    code, out, err = verify(capsys, "cubicle/blueprint")
    assert code == 1 and f"{V0}: FAILED" in out and "read-only" not in err, out + err


def test_verify_of_a_logged_dataset_on_a_read_only_data_root_says_ok(root, read_only, capsys):
    rng = np.random.default_rng(0)
    o = rng.normal(size=(5, 5)).astype(np.float32)
    table = T.transitions_table(
        episode=np.zeros(4),
        step=np.arange(4),
        obs=o[:-1],
        action=np.array([0, 1, 2, 3]),
        reward=np.zeros(4),
        next_obs=o[1:],
        terminated=np.array([False, False, False, True]),
        truncated=np.zeros(4, bool),
        robot=np.zeros(4),
        cell=np.arange(4),
        target=np.full(4, 7),
    )
    inputs = T.logging_inputs(
        parent="tiny/blueprint",
        parent_version="abc",
        behaviour={"kind": "noisy-shortest", "shortest_prob": 0.5},
        steps=4,
        seed=0,
        settings={"num_envs": 1, "obs": "goal", "reward": "geodesic", "max_steps": 4},
        libraries={"numpy": "x"},
    )
    meta = {"observations": {"preset": "goal", "names": list("abcde")}, "behaviour_text": "test"}
    version, _ = T.write_logged(LOGGED, inputs, table, meta)
    read_only()
    code, out, err = verify(capsys, LOGGED)
    assert (code, out.strip(), err) == (0, f"{version}: ok", ""), out + err
