"""A failed ``verify`` says how to get the version back with commands that work for that dataset: ``make dataset``
for a built-in scene, the build from its own scene file for a user's scene (``make dataset SCENE=office`` would not
find it), and the pull of the failed version's own tag."""

import pytest

from dtradar_data import cli
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import writing

V0 = "0123456789abcdef"


def damaged(name):
    ds = synthetic_dataset(5, 3, name=name)
    vdir = writing.write_version(name, V0, ds.table, {**ds.meta, "rt": {"max_depth": 5}})
    data = bytearray((vdir / "cells.parquet").read_bytes())
    data[100] ^= 0x01
    (vdir / "cells.parquet").write_bytes(bytes(data))


@pytest.mark.parametrize(
    "name, build",
    [
        ("cubicle/dynamic", "`make dataset SCENE=cubicle` (or `python -m dtradar_data build --scene cubicle"),
        ("cubicle/moving", "`make dataset SCENE=cubicle VARIANT=moving`"),
        ("office/blueprint", "`python -m dtradar_data build --scene path/to/office.toml --variant blueprint`"),
    ],
)
def test_a_failed_verify_names_a_build_and_a_pull_that_work(root, capsys, name, build):
    damaged(name)
    assert cli.main(["verify", name]) == 1
    err = capsys.readouterr().err
    assert f"rebuild it with {build}" in err and f"re-pull it (`python -m dtradar_data pull {name}@v0`)" in err
    assert "<" not in err and (name.startswith("cubicle") or "make dataset" not in err)
