"""A partial build records the device it traces on, and is resumed on that device only: the device is no part of the
version, so a resume on the other one would store a table traced on both. (No GPU needed: the CUDA partial build is
faked by its recorded state.)"""

import json
from dataclasses import replace

import pytest

from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.core.layout import work_root
from dtradar_data.geometry.occupancy import occupancy
from dtradar_data.pipeline import static_build
from dtradar_data.pipeline.batches import batch_dir, batch_layout
from dtradar_data.pipeline.config import BuildConfig, scene_config
from dtradar_data.pipeline.inputs import build_inputs
from dtradar_data.pipeline.resume import RESUME_FILE, claim_device
from dtradar_data.rt.settings import RTSettings
from dtradar_data.scenes import load_scene_spec
from dtradar_data.store import local, versions


def test_a_partial_build_traced_on_cuda_is_not_resumed_on_the_cpu_and_the_error_says_how_to_go_on(
    root, tmp_path, tiny_room
):
    path = tmp_path / "room.toml"
    path.write_text(tiny_room)
    spec = load_scene_spec(str(path), "blueprint")
    # Sionna's own solver, which traces on either device (batch-independent tracing is the CPU's only)
    rt = RTSettings(max_depth=1, batch_size=4, device="cpu", batch_independent=False)
    config = BuildConfig(scene="tiny", coverage_map=False, progress=False, rt=rt)
    cfg = scene_config(config, spec)
    version = versions.version_id(build_inputs(spec, cfg))
    assert version == versions.version_id(build_inputs(spec, replace(cfg, rt=replace(rt, device="cuda"))))
    work = work_root() / spec.scene / spec.variant / version
    where = batch_dir(work, cfg.rt, batch_layout(int((~occupancy(spec)).sum()), cfg.rt))
    where.mkdir(parents=True)
    (where / "batch_00000.npz").write_bytes(b"traced on the GPU")
    (work / RESUME_FILE).write_text(json.dumps({"device": "cuda"}))  # what a CUDA build killed midway leaves

    with pytest.raises(InvalidSettingError, match="traced 1 finished part.* on the CUDA") as e:
        static_build.build_one(spec, config)
    assert "--rt.device cpu" in str(e.value) and "--rt.device cuda" in e.value.hint and f"rm -r {work}" in e.value.hint
    assert (where / "batch_00000.npz").read_bytes() == b"traced on the GPU", "the partial build is left as it was"
    assert json.loads((work / RESUME_FILE).read_text()) == {"device": "cuda"}
    assert not local.version_exists(f"{spec.scene}/{spec.variant}", version)

    assert claim_device(work, replace(cfg.rt, device="cuda"), spec.name) == "cuda", "the same device resumes it"
    (where / "batch_00000.npz").unlink()  # a partial build with nothing traced yet: its record is just replaced
    assert claim_device(work, cfg.rt, spec.name) == "cpu"
    assert json.loads((work / RESUME_FILE).read_text()) == {"device": "cpu"}
    # the default, batch-independent tracing, is the CPU's whatever --rt.device auto finds
    assert claim_device(work, replace(cfg.rt, device="auto", batch_independent=True), spec.name) == "cpu"
