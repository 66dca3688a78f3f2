"""A writer killed with SIGKILL in the middle of a checkpoint write leaves a ``last.pt`` that loads: the previous
checkpoint or the new one, whole. A real process (``kill -9``) rewrites a 4 MB checkpoint in a loop through
``save_torch_atomic``; one kill lands while a write is provably under way (its file is open, the state is being
pickled: an in-place ``torch.save`` left the 0-byte ``last.pt`` of the issue here), another a moment after a write
starts. What a killed write leaves behind is a hidden ``.last.pt.*.tmp`` file, never a ``*.pt`` that ``--resume`` or
``load_policy`` could pick up."""

import signal
import subprocess
import sys
import textwrap
import time

import pytest

from dtradar_rl.agents.checkpoints import read_checkpoint

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")

WRITER = textwrap.dedent("""
    import sys
    import time
    from pathlib import Path

    import torch

    from dtradar_rl.agents.checkpoints import save_torch_atomic

    path, first, pause_at = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])


    class Midway:
        # pickled inside torch.save, after the target file was opened; loads back as the plain int
        def __init__(self, step):
            self.step = step

        def __reduce__(self):
            print(f"midway {self.step}", flush=True)
            if self.step == pause_at:
                time.sleep(30)  # the parent kills us here
            return int, (self.step,)


    weights = torch.arange(1_000_000, dtype=torch.float32)
    for step in range(first, first + 10_000):
        print(f"writing {step}", flush=True)
        save_torch_atomic({"format": "kill-test/1", "step": step, "weights": weights + step,
                           "midway": Midway(step)}, path)
""")


def kill_mid_write(path, first: int, kill_at: int, *, when: str) -> None:
    """Run a writer from step ``first``; SIGKILL it while it writes step ``kill_at``: ``when="midway"`` with the
    write's file open (the writer pauses there), ``when="start"`` 2 ms after it announces the write."""
    pause_at = kill_at if when == "midway" else -1
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), str(first), str(pause_at)], stdout=subprocess.PIPE, text=True
    )
    try:
        for line in proc.stdout:
            if line.split() == [{"midway": "midway", "start": "writing"}[when], str(kill_at)]:
                if when == "start":
                    time.sleep(0.002)
                proc.send_signal(signal.SIGKILL)
                break
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL


def assert_last_pt_is_whole(directory, killed_at: int) -> list[str]:
    state = read_checkpoint(directory / "last.pt", ("kill-test/1",), what="kill-test checkpoint")
    assert killed_at - 1 <= state["step"] <= killed_at, "the last complete write, or the killed one whole"
    assert state["midway"] == state["step"]
    assert state["weights"][-1].item() == 999_999 + state["step"], "the tensor is the one of that step"
    assert [p.name for p in directory.glob("*.pt")] == ["last.pt"]
    leftovers = sorted(p.name for p in directory.iterdir() if p.name != "last.pt")
    assert all(n.startswith(".last.pt.") and n.endswith(".tmp") for n in leftovers), leftovers
    return leftovers


@pytest.mark.slow  # a writer process killed mid-write: seconds (make test-all)
def test_a_checkpoint_writer_killed_mid_write_leaves_a_last_pt_that_loads(tmp_path):
    kill_mid_write(tmp_path / "last.pt", 0, 2, when="midway")
    assert_last_pt_is_whole(tmp_path, 1)
    assert read_checkpoint(tmp_path / "last.pt", ("kill-test/1",), what="")["step"] == 1, "write 2 never landed"
    assert len(assert_last_pt_is_whole(tmp_path, 1)) == 1, "the killed write's temporary file is left, hidden"

    kill_mid_write(tmp_path / "last.pt", 3, 5, when="start")
    assert_last_pt_is_whole(tmp_path, 5)
