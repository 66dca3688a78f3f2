"""``verify`` beside a process that is writing a version of the same dataset: the unfinished version is reported as
being written by that process (its pid), never as damaged or as not built, and no file of it is read. Versions are
staged and renamed into place whole, so what a reader can meet is a build still tracing (no version yet) or a damaged
logged version being logged again; once the writer is killed, its version is judged as it is."""

import numpy as np

from dtradar_data.cli import main
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import logged as T
from dtradar_data.store import writing

V0, V1 = "0123456789abcdef", "fedcba9876543210"

#: A build of cubicle/blueprint version V1 that stops while it traces: the build lock held, nothing stored yet.
BUILDING = f"""
import time

from dtradar_data.core.ids import DatasetId
from dtradar_data.pipeline import storing


def make(work_dir, tmp):
    print("midway", flush=True)  # the parent verifies here, then kills us
    time.sleep(120)


storing.store_version(DatasetId("cubicle", "blueprint", None), "{V1}", make, progress=lambda w: "3 of 12 batches")
"""

LOGGED = "tiny/blueprint/noisy-shortest"

#: The lock ``make log`` holds while it logs a version again (the rollout, then the write that replaces it).
LOGGING = """
import sys
import time

from dtradar_data.store import logged as T

with T.logging_lock(T.parse_logged_id(sys.argv[1]), sys.argv[2]):
    print("midway", flush=True)
    time.sleep(120)
"""


def verify(capsys, *args):
    code = main(["verify", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_verify_during_a_build_names_the_builder_and_reports_nothing_damaged(root, paused_process, capsys):
    build = paused_process(BUILDING)
    build.wait_for("midway")
    who = f"pid {build.pid}"

    code, out, err = verify(capsys, "cubicle/blueprint")  # nothing stored yet: not "not built"
    assert code == 2 and "has not been built" not in err
    assert f"error: version {V1} of cubicle/blueprint is being written by {who}" in err
    assert f"which is building cubicle/blueprint version {V1}" in err and "unfinished, not damaged" in err
    again = f"`python -m dtradar_data verify cubicle/blueprint@{V1[:12]}`"
    assert f"how to fix: verify it once that process has finished ({again})" in err

    ds = synthetic_dataset(5, 3, name="cubicle/blueprint")
    writing.write_version("cubicle/blueprint", V0, ds.table, {**ds.meta, "rt": {}})
    code, out, err = verify(capsys, "cubicle/blueprint")
    assert code == 0 and f"{V0}: ok" in out, out + err
    assert f"{V1}: being written by {who}" in out and "not verified" in out and "FAILED" not in out
    code, out, err = verify(capsys, f"cubicle/blueprint@{V1[:8]}")
    assert code == 2 and f"being written by {who}" in err

    build.kill()  # its lock is free: the version is neither being written nor stored
    code, out, err = verify(capsys, "cubicle/blueprint")
    assert code == 0 and out.strip() == f"{V0}: ok"
    code, out, err = verify(capsys, f"cubicle/blueprint@{V1[:8]}")
    assert code == 2 and f"has no version '{V1[:8]}'" in err and "being written" not in err


def tiny_table():
    rng = np.random.default_rng(0)
    o = rng.normal(size=(5, 5)).astype(np.float32)
    return T.transitions_table(
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


def test_a_damaged_logged_version_being_logged_again_is_reported_as_being_written_not_failed(
    root, paused_process, capsys
):
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
    version, vdir = T.write_logged(LOGGED, inputs, tiny_table(), meta)
    (vdir / "meta.json").unlink()  # damaged: `make log` with the same settings logs it again and replaces it
    logger = paused_process(LOGGING, LOGGED, version)
    logger.wait_for("midway")

    for name in (LOGGED, f"{LOGGED}@{version}"):
        code, out, err = verify(capsys, name)
        assert code == 2 and "FAILED" not in out, out + err
        assert f"version {version} of {LOGGED} is being written by pid {logger.pid}" in err
        assert f"which is logging {LOGGED}@{version}" in err

    logger.kill()  # nobody is replacing it any more: it is what it is, damaged
    code, out, err = verify(capsys, LOGGED)
    assert code == 1 and f"{version}: FAILED" in out and "meta.json is missing" in out
