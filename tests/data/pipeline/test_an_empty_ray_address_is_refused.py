"""``python -m dtradar_data build --executor ray --ray-address ""`` is refused naming the flag (exit status 2), as
``python -m dtradar_rl offline-bench`` refuses it, before Ray starts or anything is traced: an empty address started
a local Ray, as leaving the flag out does, while it names a cluster."""

import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline.config import BuildConfig


@pytest.mark.parametrize("address", ["", "  "])
def test_an_empty_ray_address_is_refused_and_says_how_to_give_one_or_drop_it(root, monkeypatch, capsys, address):
    import ray

    def init(*args, **kwargs):
        raise AssertionError("a Ray was started for an address that should have been refused first")

    monkeypatch.setattr(ray, "init", init)
    assert cli.main(["build", "--scene", "cubicle", "--executor", "ray", "--ray-address", address]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and "--ray-address" in first and "empty" in first, err
    assert "drop --ray-address" in err and "how to fix:" in err and "Traceback" not in err, err
    assert not root.exists() or not any(root.rglob("*.parquet")), "nothing built"
    with pytest.raises(InvalidSettingError, match="--ray-address"):
        BuildConfig(scene="cubicle", executor="ray", ray_address=address)
