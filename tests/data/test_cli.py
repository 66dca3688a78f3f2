"""The dtradar_data CLI: subcommands, positional NAME, clean typed errors with exit status 2."""

import subprocess
import sys

import pytest

from dtradar_data import cli
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.store import local as store
from dtradar_data.store import writing

V0, V1 = "0123456789abcdef", "fedcba9876543210"


@pytest.fixture()
def root(root, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return root


def put(version=V0, name="cubicle/blueprint", **meta):
    ds = synthetic_dataset(6, 4, name=name)
    return writing.write_version(name, version, ds.table, {**ds.meta, "rt": {"max_depth": 5}, **meta})


def test_list_shows_built_and_unbuilt_datasets(root, capsys):
    put()
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert "cubicle/blueprint" in out and "v0" in out and "meeting/dynamic" in out and "(not built)" in out


def test_info_takes_a_positional_name_with_a_revision(root, capsys):
    put(V0)
    put(V1, rt={"max_depth": 6})
    assert cli.main(["info", "cubicle/blueprint@v0"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"cubicle/blueprint@v0  (version {V0}") and V1 in out and "cells.parquet" in out


def test_unknown_name_prints_one_clean_error_and_exits_2(root, capsys):
    assert cli.main(["info", "cubical/blueprint"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: unknown dataset 'cubical/blueprint'; did you mean 'cubicle/blueprint'")
    assert "Traceback" not in err


def test_unbuilt_dataset_says_how_to_build_it(root, capsys):
    assert cli.main(["verify", "meeting/blueprint"]) == 2
    assert "make dataset SCENE=meeting" in capsys.readouterr().err


def test_verify_passes_then_fails_after_a_flipped_byte(root, capsys):
    path = put()
    assert cli.main(["verify", "cubicle/blueprint"]) == 0
    assert f"{V0}: ok" in capsys.readouterr().out
    data = bytearray((path / "cells.parquet").read_bytes())
    data[100] ^= 0x01
    (path / "cells.parquet").write_bytes(bytes(data))
    assert cli.main(["verify", "cubicle/blueprint"]) == 1
    out = capsys.readouterr().out
    assert f"{V0}: FAILED" in out and "cells.parquet: sha256 differs" in out


def test_build_calls_the_pipeline_with_the_parsed_config(root, capsys, monkeypatch):
    builder = pytest.importorskip("dtradar_data.pipeline.builder")
    seen = []

    def fake_build(config):
        seen.append(config)
        put()
        return [store.load("cubicle/blueprint")]

    monkeypatch.setattr(builder, "build", fake_build)
    assert cli.main(["build", "--scene", "cubicle", "--variant", "blueprint", "--rt.max-depth", "3"]) == 0
    assert seen[0].scene == "cubicle" and seen[0].variant == "blueprint" and seen[0].rt.max_depth == 3
    assert f"cubicle/blueprint@v0: version {V0}" in capsys.readouterr().out


def test_python_dash_m_reports_typed_errors_without_a_traceback(root):
    proc = subprocess.run(
        [sys.executable, "-m", "dtradar_data", "info", "cubical/blueprint"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: unknown dataset") and "Traceback" not in proc.stderr


def test_help_lists_every_subcommand(root, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    for name in ("build", "list", "info", "verify", "cards", "publish", "pull"):
        assert name in out
