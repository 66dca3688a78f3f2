"""``python -m dtradar_rl offline-bench --executor ray --ray-address <address>`` where no Ray cluster answers is
refused (exit status 2, the address and how to fix it) before the first dataset is logged: the address was probed
only when the trainings started, after every log was stored (and the online agent trained). A tiny synthetic twin."""

import socket

from dtradar_rl.cli import main

TINY = [
    "--scene", "synthetic-8x6", "--behaviours", "random", "--algorithms", "bc", "--seeds", "0", "--variants",
    "blueprint", "--steps", "40", "--num-envs", "4", "--n-steps", "2", "--pairs", "4", "--no-fqe", "--no-tabular",
]  # fmt: skip


def free_port() -> int:
    """A local port nothing listens on (bound once by the OS, then closed)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_dead_ray_address_is_refused_before_any_dataset_is_logged(root, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    address = f"127.0.0.1:{free_port()}"
    out = tmp_path / "bench"
    assert main(["offline-bench", *TINY, "--executor", "ray", "--ray-address", address, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--ray-address {address}: nothing answers" in err.splitlines()[0], err
    assert "how to fix:" in err and "Traceback" not in err and "unexpected" not in err, err
    assert not (root / "logged").exists(), "no logged dataset stored"
    assert not out.exists(), "no benchmark started in --out"
