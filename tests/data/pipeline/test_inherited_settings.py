"""A derived dataset checks every input it inherits: a differential build keeps its parent blueprint's rows, so it
starts only from a stored blueprint built with the same inputs (the scene but its objects, every RT setting in the
version, the schema and library versions, the per-path table), and otherwise refuses before anything is traced,
naming what differs and how to fix it, with nothing changed on disk. (No ray tracer: the parents are synthetic
tables stored with the metadata a real build writes, and tracing is made to fail the test.)"""

import json
from dataclasses import replace

import pytest

from dtradar_data.core.errors import DatasetNotFoundError, InvalidSettingError
from dtradar_data.core.schema import SCHEMA_VERSION
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.pipeline.builder import build
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.parent import differential_parent_version
from dtradar_data.pipeline.synthetic import synthetic_table
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store import versions, writing

#: The tiny room gets a dynamic twin: one more box.
DYNAMIC = """
[dynamic]
description = "a second box"
[[dynamic.add]]
name = "box_02"
kind = "box"
material = "wood"
x_m = 1.75
y_m = 1.25
width_m = 0.4
length_m = 0.4
height_m = 0.8
"""


@pytest.fixture
def room(tmp_path, tiny_room):
    path = tmp_path / "room.toml"
    path.write_text(tiny_room + DYNAMIC)
    return path


@pytest.fixture
def config(room):
    return BuildConfig(
        scene=str(room),
        variant="dynamic",
        differential=True,
        per_path=False,
        coverage_map=False,
        progress=False,
        rt=RTSettings(max_depth=1, samples_per_src=2_000, device="cpu"),
    )


@pytest.fixture(autouse=True)
def no_tracing(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the build traced although it should have been refused first")

    monkeypatch.setattr(static_build, "RayTracer", refuse)
    monkeypatch.setattr(tracing, "trace_grid", refuse)


def store_parent(room, config, version: str, **changes) -> None:
    """A stored tiny-room/blueprint as the builder would write it with ``config``, then ``changes`` to its
    ``meta.json`` (a dict is merged into the recorded one)."""
    spec = load_scene_spec(str(room), "blueprint")
    cfg = scene_config(config, spec)
    blocked = occupancy(spec)
    cells = synthetic_table(spec.grid.nx, spec.grid.ny, blocked, cell_m=spec.grid.cell_m)
    meta = {
        "scene_spec": spec.to_dict(),
        "rt": {**cfg.rt.hashed(), "reduction": "test"},
        "grid": spec.grid.to_dict(),
        "transmitter": spec.tx.to_dict(),
        "rx_height_m": spec.rx_height_m,
        "robot_height_m": spec.robot_height_m,
        "library_versions": versions.library_versions(),
        "schema_version": SCHEMA_VERSION,
    }
    path = writing.write_version("tiny-room/blueprint", version, cells, meta) / "meta.json"
    stored = json.loads(path.read_text())  # as an older build (other settings, libraries, schema) wrote it
    for key, value in changes.items():
        stored[key] = {**stored[key], **value} if isinstance(value, dict) else value
    path.write_text(json.dumps(stored))


def on_disk(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    ("parent_meta", "named"),
    [
        ({"rt": {"frequency_hz": 5e9}}, "--rt.frequency-hz 5e+09 in the parent, 2.4e+09 here"),
        ({"rt": {"seed": 7}}, "--rt.seed 7 in the parent, 42 here"),
        ({"rt": {"samples_per_src": 10_000}}, "--rt.samples-per-src 10000 in the parent, 2000 here"),
        ({"rt": {"diffraction": True}}, "--rt.diffraction True in the parent, False here"),
        ({"library_versions": {"sionna-rt": "0.0.1"}}, "sionna-rt 0.0.1 in the parent"),
        ({"schema_version": SCHEMA_VERSION - 1}, "schema version"),
        ({"scene_spec": {"rx_height_m": 0.5}}, "scene rx_height_m 0.5 in the parent, 1 here"),
        ({"scene_spec": {"grid": {"x0_m": 0.0, "y0_m": 0.0, "cell_m": 0.25, "nx": 4, "ny": 3}}}, "scene grid"),
    ],
)
def test_a_differential_build_refuses_a_parent_built_with_other_inputs_and_names_them(
    root, room, config, parent_meta, named
):
    store_parent(room, config, "a" * 16, **parent_meta)
    before = on_disk(root)
    with pytest.raises(InvalidSettingError) as err:
        build(config)
    assert named in err.value.message
    assert "tiny-room/blueprint@v0" in err.value.message
    assert "drop --differential" in err.value.hint and "--variant blueprint" in err.value.hint
    assert on_disk(root) == before, "a refused build changed the data root"


def test_a_parent_traced_with_another_solver_is_refused_and_the_solvers_are_named(root, room, config):
    stock = replace(config, rt=replace(config.rt, batch_independent=False))
    store_parent(room, stock, "a" * 16)  # built before batch-independent tracing was the default
    with pytest.raises(InvalidSettingError) as err:
        build(config)
    assert "the parent was traced with Sionna's own solver (--rt.no-batch-independent)" in err.value.message
    assert "this build traces batch-independently" in err.value.message


def test_a_batch_independent_parent_is_refused_by_a_build_with_sionnas_solver(root, room, config):
    store_parent(room, config, "a" * 16)  # batch-independent, the default
    with pytest.raises(InvalidSettingError) as err:
        build(replace(config, rt=replace(config.rt, batch_independent=False)))
    assert "the parent was traced batch-independently" in err.value.message
    assert "this build traces with Sionna's own solver" in err.value.message


def test_a_stock_parent_traced_in_other_batches_is_refused_by_a_stock_build(root, room, config):
    stock = replace(config, rt=replace(config.rt, batch_independent=False))
    store_parent(room, stock, "a" * 16, rt={"batch_size": 256})
    with pytest.raises(InvalidSettingError, match="--rt.batch-size 256 in the parent, 1024 here"):
        build(stock)


def test_a_parent_without_the_per_path_table_is_refused_when_the_build_stores_one(root, room, config):
    store_parent(room, config, "a" * 16)
    with pytest.raises(InvalidSettingError, match="per-path table"):
        build(replace(config, per_path=True))


def test_the_differential_starts_from_the_newest_blueprint_with_the_same_inputs_not_simply_the_newest(
    root, room, config
):
    store_parent(room, config, "a" * 16)  # v0: this build's settings
    store_parent(room, config, "b" * 16, rt={"frequency_hz": 5e9})  # v1, the newest: another frequency
    spec = load_scene_spec(str(room), "dynamic")
    assert differential_parent_version(spec, config) == "a" * 16
    assert differential_parent_version(spec, replace(config, rt=replace(config.rt, frequency_hz=5e9))) == "b" * 16
    store_parent(room, config, "c" * 16)  # v2: the same settings again, newer
    assert differential_parent_version(spec, config) == "c" * 16


def test_the_message_names_the_closest_stored_blueprint_when_none_matches(root, room, config):
    store_parent(room, config, "a" * 16, rt={"seed": 7})  # v0: one setting off
    store_parent(room, config, "b" * 16, rt={"seed": 8, "max_depth": 3})  # v1, the newest: two off
    with pytest.raises(InvalidSettingError) as err:
        build(config)
    assert "the closest of 2, tiny-room/blueprint@v0" in err.value.message
    assert "--rt.seed 7 in the parent, 42 here" in err.value.message


def test_a_differential_build_without_any_stored_blueprint_says_to_build_it_first(root, config):
    with pytest.raises(DatasetNotFoundError) as err:
        build(config)
    assert "--differential" in err.value.message and "--variant blueprint" in err.value.hint
    assert not root.exists() or not any(root.rglob("*.parquet"))


def test_a_pose_twin_checks_its_parent_pose_twin_blueprint_the_same_way(root, room, config):
    """An antenna-pose-error twin's differential parent is the pose twin's blueprint (same seeded pose); another
    pose seed moves the transmitter, which its rows depend on."""
    pose = replace(config, tx_pose_error=(0.3, 5.0))
    blueprint, twin = static_build.build_specs(replace(pose, variant="all"))
    cfg = scene_config(pose, blueprint)
    cells = synthetic_table(blueprint.grid.nx, blueprint.grid.ny, occupancy(blueprint), cell_m=blueprint.grid.cell_m)
    meta = {
        "scene_spec": blueprint.to_dict(),
        "rt": cfg.rt.hashed(),
        "grid": blueprint.grid.to_dict(),
        "library_versions": versions.library_versions(),
        "schema_version": SCHEMA_VERSION,
    }
    writing.write_version(f"{twin.scene}/blueprint", "d" * 16, cells, meta)
    assert differential_parent_version(twin, pose) == "d" * 16
    with pytest.raises(InvalidSettingError, match="scene tx differs"):
        build(replace(pose, tx_pose_seed=1))
