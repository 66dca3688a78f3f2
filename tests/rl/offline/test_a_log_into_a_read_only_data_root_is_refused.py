"""``python -m dtradar_rl log`` into a read-only data root (a shared mirror, a container image) is refused with exit
status 2 and the data root's fix, before anything is rolled out or written (it ended in exit 3 with a raw
PermissionError). Skipped where chmod does not stop writes (as root). A tiny synthetic twin."""

import pytest

from dtradar_data.core.errors import DataRootError
from dtradar_rl.cli import main
from dtradar_rl.offline import logged
from dtradar_rl.offline.logged import LogConfig, log_dataset, log_families

ARGS = ["--scene", "synthetic-10x8", "--steps", "120", "--num-envs", "12", "--max-steps", "15", "--no-minari"]


@pytest.fixture()
def nothing_rolls(monkeypatch):
    def rolled(*args, **kwargs):
        raise AssertionError("a behaviour was rolled out into a data root that cannot hold it")

    monkeypatch.setattr(logged, "roll", rolled)
    monkeypatch.setattr(logged, "medium_agent", rolled)


@pytest.mark.parametrize("behaviour", ["noisy-shortest", "all"])
def test_a_log_into_a_read_only_data_root_exits_2_naming_it_before_anything_is_rolled_out(
    root, read_only, nothing_rolls, capsys, behaviour
):
    read_only()
    assert main(["log", *ARGS, "--behaviour", behaviour]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: data root {root} is read-only"), err
    assert "how to fix:" in err and "DTRADAR_DATA_ROOT" in err, err
    assert "Traceback" not in err and "unexpected" not in err and "PermissionError" not in err, err
    assert list(root.iterdir()) == [], "nothing written"


def test_log_dataset_and_log_families_refuse_a_read_only_data_root_too(root, read_only, nothing_rolls):
    read_only()
    cfg = LogConfig(scene="synthetic-10x8", steps=120, num_envs=12, max_steps=15, minari=False)
    for log in (log_dataset, log_families):
        with pytest.raises(DataRootError, match="read-only"):
            log(cfg)
    assert list(root.iterdir()) == []
