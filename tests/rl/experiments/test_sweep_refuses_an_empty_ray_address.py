"""``python -m dtradar_rl sweep --ray-address ""`` is refused naming the flag, as offline-bench refuses it, before
any run starts: an empty address started a local Ray, as leaving the flag out does, while it names a cluster."""

import pytest

from dtradar_rl.cli import main
from dtradar_rl.experiments.sweep import SweepConfig
from dtradar_rl.task.config import ConfigError


@pytest.mark.parametrize("address", ["", "  "])
def test_an_empty_ray_address_is_refused_and_says_how_to_give_one_or_drop_it(root, monkeypatch, capsys, address):
    import ray

    def init(*args, **kwargs):
        raise AssertionError("a Ray was started for an address that should have been refused first")

    monkeypatch.setattr(ray, "init", init)
    assert main(["sweep", "--scenes", "synthetic-8x6", "--seeds", "0", "--ray-address", address]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and "--ray-address" in first and "empty" in first, err
    assert "drop --ray-address" in err and "how to fix:" in err and "Traceback" not in err, err
    with pytest.raises(ConfigError, match="--ray-address"):
        SweepConfig(scenes=("synthetic-8x6",), ray_address=address).validate()
