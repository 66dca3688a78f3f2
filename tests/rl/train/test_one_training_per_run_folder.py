"""One training per run folder at a time: a second ``train`` into a folder that a live run holds is refused at once,
naming the holder's pid and the folder, with not a byte of the folder changed; the lock dies with its process, so
after a ``kill -9`` of the holder the next run into the folder trains."""

import hashlib
import os

import pytest

from dtradar_data.core.errors import InUseError
from dtradar_data.core.folder_lock import LOCK_FILE
from dtradar_rl.cli import main
from dtradar_rl.task.runs import held_out_folder
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train

SCENE = "synthetic-4x3"
ARGS = ["--scene", SCENE, "--preset", "tuned", "--obs", "goal", "--num-envs", "8", "--hidden", "16"]
ARGS += ["--batch-size", "32", "--learning-starts", "50", "--threads", "1", "--no-verbose", "--checkpoint-every", "0"]
ARGS += ["--total-env-steps", "200"]

#: ``python -m dtradar_rl train ...`` that stops in its training loop: its folder held, its config.json written.
HOLDER = """
import sys
import time

from dtradar_rl.train import dqn


def paused(run, callback, t_start):
    print("midway", flush=True)  # the parent starts its own run into the folder here, then kills us
    time.sleep(120)


dqn._training_loop = paused
from dtradar_rl.cli import main

sys.exit(main(sys.argv[1:]))
"""


def snapshot(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.mark.slow  # a training held in a worker process: seconds (make test-all)
def test_a_second_training_into_a_run_folder_in_use_is_refused_naming_the_holders_pid(tmp_path, paused_process, capsys):
    out = tmp_path / "run"
    holder = paused_process(HOLDER, "train", *ARGS, "--out", out)
    holder.wait_for("midway")
    before = snapshot(out)
    assert "config.json" in before

    for extra in ([], ["--resume"]):
        assert main(["train", *ARGS, "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and "Traceback" not in err
        assert f"--out {out} is in use by pid {holder.pid}" in err
        assert f"training {SCENE}/blueprint (tuned)" in err and "would interleave" in err
        assert "how to fix: wait until that one ends (or stop it), or pick another --out" in err
        assert snapshot(out) == before, "the refused run read nothing there and wrote nothing"

    holder.kill()  # kill -9: the kernel frees its lock; its lock file stays with the dead holder's pid in it
    assert (out / LOCK_FILE).is_file()
    assert main(["train", *ARGS, "--out", str(out)]) == 0
    assert (out / "model.pt").is_file() and (out / "curves.csv").is_file()
    assert not (out / LOCK_FILE).exists(), "a run that ends takes its lock file with it"


def test_a_run_folder_held_in_this_process_is_refused_too_and_a_free_one_is_left_as_it_was(tmp_path):
    out = tmp_path / "run"
    cfg = config_for("tuned", scene=SCENE, out=str(out), num_envs=8, total_env_steps=200, hidden=(16,))
    with held_out_folder(out, "evaluating something", what="job"):
        mine = rf"in use by pid {os.getpid()} \(since .*\), which is evaluating something"
        with pytest.raises(InUseError, match=mine):
            train(cfg)
    assert sorted(p.name for p in out.iterdir()) == [], "the holder's lock file went with it"
    with pytest.raises(KeyError), held_out_folder(tmp_path / "new" / "run", "failing", what="job"):
        raise KeyError("boom")
    assert not (tmp_path / "new").exists(), "a failed job leaves no folder it made"
