"""A battery of bad inputs, as a hostile but fair user would try them, against both CLIs, the Python API and the
gymnasium env: each ends in a typed error (a ``DtradarError``) or a one-line ``error: ...`` that names the offending
flag, path or value, before anything expensive runs and without writing anything. No ray tracing: the tracer is
replaced by one that fails the test if it is called."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from dtradar_data import cli as data_cli
from dtradar_data.core import layout
from dtradar_data.core.errors import (
    CorruptDatasetError,
    DataRootError,
    DtradarError,
    InvalidSettingError,
)
from dtradar_data.core.files import open_atomic, write_atomic
from dtradar_data.pipeline import builder, static_build, tracing
from dtradar_data.pipeline.config import BuildConfig
from dtradar_data.pipeline.inputs import build_inputs
from dtradar_data.pipeline.synthetic import synthetic_dataset
from dtradar_data.publish import cards, hub
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store import listing, writing
from dtradar_data.store.versions import version_id
from dtradar_rl import cli as rl_cli
from dtradar_rl.envs.nav_env import DtradarNavEnv, InvalidActionError

V0, V1 = "0123456789abcdef", "fedcba9876543210"


def put(version=V0, name="cubicle/blueprint", **meta):
    ds = synthetic_dataset(6, 4, name=name)
    return writing.write_version(name, version, ds.table, {**ds.meta, **meta})


@pytest.fixture()
def no_tracing(monkeypatch):
    """Any call into the ray tracer fails the test: bad inputs must be refused before it."""

    def traced(*args, **kwargs):
        raise AssertionError("the ray tracer was called for an input that should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", traced)
    monkeypatch.setattr(static_build, "RayTracer", traced)


def one_error_line(err: str) -> str:
    assert err.startswith("error: ") and "Traceback" not in err, err
    return err.splitlines()[0]


# -- 1. ray-tracing and build settings ------------------------------------------------------------------------------
BAD_RT = [
    ({"frequency_hz": 1.0}, "--rt.frequency-hz"),
    ({"frequency_hz": float("nan")}, "--rt.frequency-hz"),
    ({"frequency_hz": 2e11}, "--rt.frequency-hz"),
    ({"max_depth": -1}, "--rt.max-depth"),
    ({"max_depth": 11}, "--rt.max-depth"),
    ({"samples_per_src": 0}, "--rt.samples-per-src"),
    ({"batch_size": 0}, "--rt.batch-size"),
    ({"max_num_paths_per_src": -3}, "--rt.max-num-paths-per-src"),
    ({"seed": -1}, "--rt.seed"),
    ({"seed": 2**32}, "--rt.seed"),
    ({"rx_pattern": "isotropic"}, "--rt.rx-pattern"),
    ({"rx_polarization": "X"}, "--rt.rx-polarization"),
    ({"device": "tpu"}, "--rt.device"),
]


@pytest.mark.parametrize("changes, flag", BAD_RT)
def test_an_out_of_range_rt_setting_is_a_typed_error_naming_its_flag(changes, flag):
    with pytest.raises(InvalidSettingError, match=flag.replace(".", r"\.")):
        RTSettings(**changes)


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--rt.frequency-hz", "1"], "--rt.frequency-hz"),
        (["--rt.rx-pattern", "isotropic"], "--rt.rx-pattern"),
        (["--rt.seed", "-1"], "--rt.seed"),
        (["--coverage-samples", "0"], "--coverage-samples"),
        (["--coverage-samples", "-5"], "--coverage-samples"),
    ],
)
def test_the_build_command_refuses_a_bad_setting_while_parsing_and_names_its_flag(root, no_tracing, capsys, argv, flag):
    # the config's own check, not tyro's box: the error boundary's one line (exit status 2)
    assert data_cli.main(["build", "--scene", "cubicle", *argv]) == 2
    assert flag in one_error_line(capsys.readouterr().err)
    assert not root.exists()


@pytest.mark.parametrize("coverage_samples", [0, -1])
def test_coverage_settings_are_checked_when_the_config_is_made(coverage_samples):
    with pytest.raises(InvalidSettingError, match="--coverage-samples"):
        BuildConfig(coverage_samples=coverage_samples)


@pytest.mark.parametrize("frequency_hz, material", [(0.5e9, "brick"), (45e9, "brick"), (12e9, "wet_ground")])
def test_a_frequency_where_a_scene_material_is_undefined_is_refused_before_tracing(
    root, no_tracing, capsys, frequency_hz, material
):
    # 12 GHz suits every material of the blueprint but not the dynamic twin's: still nothing may be traced
    assert data_cli.main(["build", "--scene", "cubicle", "--rt.frequency-hz", str(frequency_hz)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--rt.frequency-hz" in line and material in line
    assert not (root / "datasets").exists()


def test_the_python_build_api_checks_the_scene_before_tracing(root, no_tracing):
    with pytest.raises(InvalidSettingError, match="wet_ground"):
        builder.build(BuildConfig(scene="cubicle", variant="dynamic", rt=RTSettings(frequency_hz=12e9)))


def test_a_frequency_every_material_supports_passes_the_scene_check():
    BuildConfig(rt=RTSettings(frequency_hz=5e9)).check_scene(load_scene_spec("cubicle", "dynamic"))


# -- 1. Hub repo ids ----------------------------------------------------------------------------------------------
BAD_REPOS = ["", "a b", "owner/name/extra", "-owner/name", "owner--x/name", "owner/name.git", "x" * 100]


@pytest.mark.parametrize("command", ["publish", "pull"])
@pytest.mark.parametrize("repo", BAD_REPOS)
def test_an_invalid_hub_repo_id_is_refused_before_any_network_call(root, monkeypatch, capsys, command, repo):
    def network(*args, **kwargs):
        raise AssertionError("the Hub was contacted for an invalid repo id")

    monkeypatch.setattr(hub, "_download", network)
    monkeypatch.setattr(hub, "_remote_revision", network)
    put()
    assert data_cli.main([command, "cubicle/blueprint@v0", f"--repo={repo}"]) == 2
    assert "--repo" in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("repo", BAD_REPOS[1:3])
def test_the_python_hub_api_refuses_an_invalid_repo_id(root, repo):
    with pytest.raises(InvalidSettingError, match="--repo"):
        hub.pull("cubicle/blueprint@v0", repo_id=repo)


# -- 2. nonsense that used to pass silently ------------------------------------------------------------------------
@pytest.fixture()
def env():
    e = DtradarNavEnv(synthetic_dataset(8, 6), obs="goal", reward="geodesic")
    e.reset(seed=0)
    return e


@pytest.mark.parametrize(
    "action",
    [
        1.5,
        1.0,
        "2",
        "1",
        True,
        np.bool_(False),
        4,
        -1,
        None,
        [1],
        np.array([1]),
        np.float32(1),
        np.array(1.0),
        np.int64(7),
    ],
)
def test_the_env_refuses_an_action_that_is_not_an_integer_move(env, action):
    with pytest.raises(InvalidActionError, match="not an integer in 0..3"):
        env.step(action)


@pytest.mark.parametrize("action", [0, 3, np.int64(1), np.uint8(2), np.int32(3), np.array(2), np.array(0, np.int16)])
def test_the_env_takes_python_and_numpy_integers_and_0d_integer_arrays(env, action):
    obs, reward, terminated, truncated, info = env.step(action)
    assert env.observation_space.contains(obs)


def test_the_env_refuses_a_step_before_reset():
    with pytest.raises(InvalidActionError, match="reset"):
        DtradarNavEnv(synthetic_dataset(8, 6)).step(0)


def test_the_env_with_action_checks_still_passes_gymnasiums_checker():
    from gymnasium.utils.env_checker import check_env

    check_env(DtradarNavEnv(synthetic_dataset(8, 6)), skip_render_check=True)


@pytest.mark.parametrize("extra", [["--check"], ["--rerender"], []])
def test_cards_against_a_folder_that_does_not_exist_fail_instead_of_reporting_success(root, tmp_path, capsys, extra):
    missing = tmp_path / "no-such-cards"
    assert data_cli.main(["cards", "--out", str(missing), *extra]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(missing) in line and "--out" in line


@pytest.mark.parametrize("make", ["empty folder", "file"])
def test_cards_check_against_an_empty_folder_or_a_file_fails(tmp_path, capsys, make):
    out = tmp_path / "cards"
    out.mkdir() if make == "empty folder" else out.write_text("x")
    assert data_cli.main(["cards", "--check", "--out", str(out)]) == 2
    assert str(out) in one_error_line(capsys.readouterr().err)


def test_a_garbage_card_json_is_a_typed_error_naming_the_file(tmp_path):
    d = tmp_path / "cards" / "cubicle" / "blueprint"
    d.mkdir(parents=True)
    (d / cards.CARD_INPUTS).write_text("{not json")
    with pytest.raises(CorruptDatasetError, match="card.json"):
        cards.stale_cards(tmp_path / "cards")


# -- 3. the data root and damaged versions -------------------------------------------------------------------------
@pytest.fixture()
def file_root(tmp_path, monkeypatch):
    f = tmp_path / "root-is-a-file"
    f.write_text("not a folder")
    monkeypatch.setenv(layout.ENV_DATA_ROOT, str(f))
    return f


@pytest.mark.parametrize(
    "argv",
    [
        ["list"],
        ["info", "cubicle/blueprint"],
        ["verify", "cubicle/blueprint"],
        ["build", "--scene", "cubicle"],
        ["pull", "cubicle/blueprint@v0"],
    ],
)
def test_a_data_root_that_is_a_file_is_one_error_naming_it(file_root, no_tracing, capsys, argv):
    assert data_cli.main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(file_root) in line and "not a folder" in line


def test_a_data_root_below_a_file_is_refused_naming_the_file(tmp_path, monkeypatch):
    (tmp_path / "f").write_text("x")
    monkeypatch.setenv(layout.ENV_DATA_ROOT, str(tmp_path / "f" / "root"))
    with pytest.raises(DataRootError, match=str(tmp_path / "f")) as err:
        layout.datasets_root()
    assert layout.ENV_DATA_ROOT in str(err.value)


@pytest.fixture()
def read_only_root(root, monkeypatch):
    root.mkdir(parents=True)
    if os.geteuid() == 0:  # root ignores permission bits; make the data root read-only the way access(2) sees it
        real_access = os.access
        monkeypatch.setattr(layout.os, "access", lambda p, mode: False if Path(p) == root else real_access(p, mode))
    else:
        root.chmod(0o555)
    yield root
    root.chmod(0o755)


@pytest.mark.parametrize("argv", [["build", "--scene", "cubicle"], ["pull", "cubicle/blueprint@v0"]])
def test_a_read_only_data_root_is_refused_before_a_build_or_pull_starts(read_only_root, no_tracing, capsys, argv):
    assert data_cli.main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(read_only_root) in line and "read-only" in line
    assert list(read_only_root.iterdir()) == []


def test_a_read_only_data_root_still_lists(read_only_root, capsys):
    assert data_cli.main(["list"]) == 0


def test_storing_into_a_read_only_data_root_is_a_typed_error(read_only_root):
    with pytest.raises(DataRootError, match="read-only"):
        put()


def damage(path: Path, how: str) -> None:
    if how == "missing meta.json":
        (path / "meta.json").unlink()
    elif how == "garbage meta.json":
        (path / "meta.json").write_text("{not json")
    else:
        (path / "meta.json").write_text(json.dumps({"record_format": 999}))


DAMAGE = ["missing meta.json", "garbage meta.json", "foreign meta.json"]


@pytest.mark.parametrize("how", DAMAGE)
def test_verify_reports_a_damaged_version_with_exit_1_and_names_its_meta_json(root, capsys, how):
    first = put(V0)
    put(V1, title="second")
    damage(first, how)
    assert data_cli.main(["verify", "cubicle/blueprint"]) == 1
    out = capsys.readouterr().out
    assert f"{V0}: FAILED" in out and "meta.json" in out and f"{V1}: ok" in out


@pytest.mark.parametrize("how", DAMAGE)
def test_verify_of_only_the_damaged_version_by_tag_exits_1_not_not_built(root, capsys, how):
    damage(put(V0), how)
    assert data_cli.main(["verify", "cubicle/blueprint@v0"]) == 1
    assert f"{V0}: FAILED" in capsys.readouterr().out


@pytest.mark.parametrize("how", DAMAGE)
def test_list_lists_the_healthy_versions_and_flags_the_damaged_one(root, capsys, how):
    first = put(V0)
    put(V1, title="second")
    damage(first, how)
    assert data_cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert "DAMAGED cubicle/blueprint@v0" in out and "v1" in out and "meeting/blueprint" in out
    assert data_cli.main(["list", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert [v["version"] for v in rows["cubicle/blueprint"]["versions"]] == [V1]
    assert rows["cubicle/blueprint"]["damaged"][0]["version"] == V0


def test_the_listing_api_keeps_damaged_versions_apart(root):
    damage(put(V0), "missing meta.json")
    entry = next(e for e in listing.list_datasets() if e.name == "cubicle/blueprint")
    assert not entry.built and entry.damaged[0].version == V0 and "meta.json" in entry.damaged[0].problem


@pytest.mark.parametrize("how", DAMAGE)
def test_a_rebuild_into_a_damaged_version_folder_fails_before_tracing(root, no_tracing, capsys, how):
    config = BuildConfig(scene="cubicle", variant="blueprint")
    spec = load_scene_spec("cubicle", "blueprint")
    version = version_id(build_inputs(spec, config))
    folder = put(version)
    damage(folder, how)
    assert data_cli.main(["build", "--scene", "cubicle", "--variant", "blueprint"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(folder) in line


def test_storing_a_new_version_next_to_an_unreadable_one_fails_before_writing(root):
    damage(put(V0), "garbage meta.json")
    with pytest.raises(CorruptDatasetError, match="unreadable meta.json"):
        put(V1)
    assert not (root / "datasets" / "cubicle" / "blueprint" / V1).exists()


# -- 4. atomic writes --------------------------------------------------------------------------------------------
class Explodes:
    def __str__(self):
        raise RuntimeError("killed mid-write")


def test_a_write_that_fails_half_way_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "results.csv"
    write_atomic(path, "old\n")
    with pytest.raises(RuntimeError):
        with open_atomic(path) as f:
            f.write("half of the new")
            raise RuntimeError("killed")
    assert path.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == ["results.csv"]


def test_training_curves_are_written_atomically(tmp_path):
    from dtradar_rl.train.dqn import write_curves

    write_curves([(1, 10, -1.0, 5, 0, 1)], tmp_path)
    before = (tmp_path / "curves.csv").read_text()
    with pytest.raises(RuntimeError):
        write_curves([(1, 10, -1.0, 5, 0, 1), (2, 20, Explodes(), 5, 0, 0)], tmp_path)
    assert (tmp_path / "curves.csv").read_text() == before
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_offline_losses_are_written_atomically(tmp_path):
    from dtradar_rl.offline.trainer import _write_losses

    _write_losses([{"epoch": 1, "loss": 0.5}], tmp_path / "losses.csv")
    before = (tmp_path / "losses.csv").read_text()
    with pytest.raises(RuntimeError):
        _write_losses([{"epoch": 1, "loss": 0.5}, {"epoch": 2, "loss": Explodes()}], tmp_path / "losses.csv")
    assert (tmp_path / "losses.csv").read_text() == before


def test_evaluation_results_are_written_atomically(tmp_path):
    from dtradar_rl.evaluation.evaluate import write_results

    row = {"case": "a -> b", "pairs": 1, "success_rate": 1.0, "spl": 1.0}
    write_results([row], tmp_path, {"run": 1})
    before = {p.name: p.read_text() for p in tmp_path.iterdir()}
    with pytest.raises(TypeError):
        write_results([row], tmp_path, {"run": object()})  # not JSON: fails before any file is replaced
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == before


# -- the RL command line -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, flag",
    [
        (["eval", "--pairs", "0"], "--pairs"),
        (["eval", "--max-steps", "-1"], "--max-steps"),
        (["eval", "--plot-paths", "-2"], "--plot-paths"),
        (["eval", "--variants", "blueprnt"], "blueprnt"),
        (["eval", "--device", "gpu"], "--device"),
        (["cross", "--pairs", "0"], "--pairs"),
        (["cross", "--scenes", "a", "b", "--checkpoint-pattern", "model.pt"], "--checkpoint-pattern"),
        (["cross", "--variant", "dynamc"], "dynamc"),
        (["train", "--scene", "synthetic", "--lr", "0"], "--lr"),
        (["train", "--scene", "synthetic", "--max-steps", "-5"], "--max-steps"),
        (["offline", "--scene", "synthetic", "--transitions", "0"], "--transitions"),
    ],
)
def test_a_bad_rl_setting_exits_2_with_its_flag_and_writes_nothing(tmp_path, monkeypatch, capsys, argv, flag):
    monkeypatch.chdir(tmp_path)
    assert rl_cli.main([*argv, "--out", str(tmp_path / "run")]) == 2
    assert flag in one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "run").exists() and not (tmp_path / "runs").exists()


def test_every_error_in_this_battery_is_a_dtradar_error():
    for cls in (InvalidSettingError, DataRootError, CorruptDatasetError, InvalidActionError, cards.CardsNotFoundError):
        assert issubclass(cls, DtradarError)
