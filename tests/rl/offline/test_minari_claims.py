"""A log whose Minari copy another data root already holds (a shared ``MINARI_DATASETS_PATH``) is refused before
anything is logged or stored, naming both data roots and the flag or variable that fixes it; the flag it names is
one the command has."""

import pytest

from dtradar_data.store import logged as T
from dtradar_rl.cli import main
from dtradar_rl.offline.logged import LogConfig, log_dataset, log_families
from dtradar_rl.task.config import ConfigError
from dtradar_rl.task.twins import load_dataset

pytest.importorskip("minari")

SMALL = "synthetic-10x8"
ARGS = ["--scene", SMALL, "--behaviour", "noisy-shortest", "--steps", "240", "--num-envs", "12", "--max-steps", "15"]
CFG = LogConfig(scene=SMALL, behaviour="noisy-shortest", steps=240, num_envs=12, max_steps=15, verbose=False)
NAME = f"{SMALL}/blueprint/noisy-shortest"


@pytest.fixture(scope="module")
def twin():
    return load_dataset(f"{SMALL}/blueprint")


@pytest.fixture()
def shared(tmp_path, monkeypatch, twin):
    """Data root ``a`` has logged v0 with its copy in the shared Minari folder; data root ``b`` is current."""
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "shared"))
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "a"))
    log_dataset(CFG, twin)
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(tmp_path / "b"))
    return tmp_path


def test_a_log_into_a_second_data_root_whose_minari_folder_is_claimed_is_refused_before_anything_is_stored(
    shared, twin, capsys
):
    import dataclasses

    other = dataclasses.replace(CFG, seed=1)  # another version, also v0 of its own root
    for log in (lambda: log_dataset(other, twin), lambda: log_families(other, twin)):
        with pytest.raises(ConfigError) as e:
            log()
        assert str(shared / "a") in e.value.message and str(shared / "b") in e.value.message, "both data roots"
        assert "nothing was logged or stored" in e.value.message
        assert "MINARI_DATASETS_PATH" in e.value.hint and "--no-minari" in e.value.hint
        assert "overwrite" not in str(e.value), "no Python argument the command does not have"
        assert not (shared / "b").exists(), "not a byte of the second data root is written"

    assert main(["log", *ARGS, "--seed", "1"]) == 2  # the command: exit 2, still nothing stored
    assert not (shared / "b").exists()
    assert "--no-minari" in capsys.readouterr().err

    assert main(["log", *ARGS, "--seed", "1", "--no-minari"]) == 0, "the flag the hint names exists and works"
    assert T.load_logged(NAME).tag == "v0"
    with pytest.raises(ConfigError, match="nothing was logged or stored"):
        log_dataset(other, twin)  # the stored version's copy is refused up front too
    assert not (shared / "b" / "minari").exists()


def test_a_copy_of_the_very_version_logged_is_shared_not_refused(shared, twin, monkeypatch):
    assert log_dataset(CFG, twin).tag == "v0", "root b logs the same inputs: the same transitions, the same copy"
    monkeypatch.setenv("DTRADAR_DATA_ROOT", str(shared / "a"))
    assert log_dataset(CFG, twin).tag == "v0", "and root a reuses its own"
