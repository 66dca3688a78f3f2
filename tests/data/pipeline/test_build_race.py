"""Two processes build the same dataset version into one data root, the second one started while the first is
mid-trace (it has written its first batch file to the shared work folder): both finish, the store ends with exactly
one version, and the scene is traced once. Before the per-version lock, the first build's cleanup deleted the work
folder under the second, which died with ``FileNotFoundError``. (Needs Sionna; the cubicle cut to 6 x 4 cells.)"""

import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.sionna

BUILDER = textwrap.dedent("""
    import sys
    import time
    from dataclasses import replace
    from pathlib import Path

    from dtradar_data.pipeline import static_build, tracing
    from dtradar_data.pipeline.config import BuildConfig
    from dtradar_data.rt.settings import RTSettings
    from dtradar_data.scenes import load_scene_spec

    role, signals = sys.argv[1], Path(sys.argv[2])


    def wait_for(name):
        deadline = time.monotonic() + 60
        while not (signals / name).exists():
            if time.monotonic() > deadline:
                sys.exit(f"{role}: gave up waiting for {name}")
            time.sleep(0.02)


    spec = load_scene_spec("cubicle", "blueprint")
    spec = replace(spec, grid=replace(spec.grid, nx=6, ny=4))
    # 8 cells a batch: 3 batch files, so "mid-trace" is a moment with a batch written and more to come
    config = BuildConfig(scene="cubicle", rt=RTSettings(max_depth=1, samples_per_src=2_000, batch_size=8,
                                                        device="cpu"), coverage_map=False, progress=False)
    real_trace_grid, real_save = tracing.trace_grid, tracing.save_batch


    def counting_trace_grid(*args, **kwargs):
        with open(signals / "traced", "a") as f:
            f.write(role + "\\n")
        return real_trace_grid(*args, **kwargs)


    def save_then_let_the_second_in(path, cells, paths):
        real_save(path, cells, paths)
        if path.name == "batch_00000.npz":  # mid-trace: start the second build, give it time to reach the lock
            (signals / "first-batch-written").touch()
            wait_for("second-building")
            time.sleep(0.5)


    tracing.trace_grid = counting_trace_grid
    if role == "first":
        tracing.save_batch = save_then_let_the_second_in
    else:
        wait_for("first-batch-written")
        (signals / "second-building").touch()
    ds = static_build.build_one(spec, config)
    print(f"{role} done: {ds.version}")
""")


@pytest.mark.slow  # worker processes or a Ray session: seconds each (make test-all)
def test_a_second_build_process_started_mid_trace_waits_and_reuses_the_one_version(root, tmp_path):
    signals = tmp_path / "signals"
    signals.mkdir()
    t0 = time.monotonic()
    procs = {
        role: subprocess.Popen(
            [sys.executable, "-c", BUILDER, role, str(signals)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for role in ("first", "second")
    }
    out = {}
    try:
        for role, proc in procs.items():
            out[role] = proc.communicate(timeout=120)
    finally:
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    for role, proc in procs.items():
        assert proc.returncode == 0, f"{role} build failed:\n{out[role][0]}\n{out[role][1][-3000:]}"
    assert (signals / "second-building").exists(), "the second build started while the first was mid-trace"

    first_version = out["first"][0].split("first done: ")[1].split()[0]
    second_version = out["second"][0].split("second done: ")[1].split()[0]
    assert first_version == second_version
    assert "already built, reusing it" in out["second"][0]
    assert (signals / "traced").read_text().split() == ["first"], "traced once, by the first build"
    stored = [p.name for p in (root / "datasets" / "cubicle" / "blueprint").iterdir() if p.is_dir()]
    assert stored == [first_version]
    assert not (root / "work" / "cubicle" / "blueprint" / first_version).exists(), "work files are cleaned up"
    assert time.monotonic() - t0 < 60
