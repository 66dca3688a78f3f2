"""A run that fails leaves nothing behind: offline makes its --out folder only when the model is saved (and removes
the folders it made, if a failure leaves them empty), and a DQN run that fails before training writes no config."""

import dataclasses

import pytest

from dtradar_data.core.errors import DtradarError
from dtradar_rl.cli import main
from dtradar_rl.offline.config import OfflineConfig
from dtradar_rl.offline.trainer import train_offline
from dtradar_rl.task.runs import no_empty_folder_on_failure
from dtradar_rl.train.config import config_for
from dtradar_rl.train.dqn import train


def test_a_failed_offline_run_leaves_no_out_folder(root, tmp_path, capsys):
    out = tmp_path / "deep" / "offline"
    argv = ["offline", "--scene", "synthetic-4x3", "--logged", "synthetic-4x3/blueprint/absent", "--n-steps", "10"]
    assert main([*argv, "--out", str(out), "--no-verbose"]) == 2
    assert "absent" in capsys.readouterr().err
    assert not (tmp_path / "deep").exists()


def test_a_failure_after_the_data_loaded_removes_the_folders_the_run_made(root, tmp_path, monkeypatch):
    import dtradar_rl.offline.trainer as trainer

    def fails(*args, **kwargs):
        raise RuntimeError("d3rlpy failed")

    monkeypatch.setattr(trainer, "to_mdp_dataset", fails)
    (tmp_path / "kept").mkdir()
    cfg = OfflineConfig(scene="synthetic-4x3", num_envs=4, transitions=40, n_steps=10, verbose=False)
    with pytest.raises(RuntimeError, match="d3rlpy failed"):
        train_offline(dataclasses.replace(cfg, out=str(tmp_path / "kept" / "a" / "b")))
    assert [p.name for p in (tmp_path / "kept").iterdir()] == []  # a/b went, the folder that was there stays


def test_only_empty_folders_the_block_made_are_removed(tmp_path):
    with pytest.raises(KeyError), no_empty_folder_on_failure(tmp_path / "x" / "y") as path:
        path.mkdir(parents=True)
        raise KeyError("boom")
    assert not (tmp_path / "x").exists()
    with pytest.raises(KeyError), no_empty_folder_on_failure(tmp_path / "x" / "y") as path:
        path.mkdir(parents=True)
        (path / "model.d3").write_text("something to keep")
        raise KeyError("boom")
    assert (tmp_path / "x" / "y" / "model.d3").is_file()
    with no_empty_folder_on_failure(tmp_path / "z") as path:  # success: nothing is removed
        path.mkdir()
    assert (tmp_path / "z").is_dir()


def test_a_dqn_run_that_fails_before_training_writes_nothing(tmp_path):
    out = tmp_path / "dqn"
    cfg = config_for(
        "tuned", scene="synthetic-4x3", pair="paper", start=(40, 40), target=(0, 0), aug_obstacles=0, out=str(out)
    )
    with pytest.raises(DtradarError, match="40"):  # the pair is off the 4 x 3 grid: found once the twin is loaded
        train(dataclasses.replace(cfg, num_envs=2, total_env_steps=10, verbose=False, threads=1))
    assert not out.exists()
