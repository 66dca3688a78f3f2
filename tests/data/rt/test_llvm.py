"""Finding a libLLVM >= 16 for Dr.Jit (no ray tracing needed)."""

from pathlib import Path

import pytest

from dtradar_data.core.errors import RayTracerUnavailableError
from dtradar_data.rt import llvm


def test_an_explicit_drjit_libllvm_path_wins(monkeypatch, tmp_path):
    lib = tmp_path / "libLLVM-18.so"
    lib.write_bytes(b"")
    monkeypatch.setenv(llvm.ENV_VAR, str(lib))
    assert llvm.find_libllvm() == lib


def test_an_explicit_path_that_does_not_exist_says_how_to_get_one(monkeypatch, tmp_path):
    monkeypatch.setenv(llvm.ENV_VAR, str(tmp_path / "nope.so"))
    with pytest.raises(RayTracerUnavailableError, match="karellen-llvm-core"):
        llvm.find_libllvm()


def test_no_llvm_anywhere_raises_a_typed_error_with_the_install_command(monkeypatch):
    monkeypatch.delenv(llvm.ENV_VAR, raising=False)
    monkeypatch.setattr(llvm, "candidates", lambda: [])
    with pytest.raises(RayTracerUnavailableError, match="apt-get install libllvm19"):
        llvm.find_libllvm()


def test_the_setup_installs_an_llvm_of_at_least_16_in_the_environment(monkeypatch):
    monkeypatch.delenv(llvm.ENV_VAR, raising=False)
    found = llvm.candidates()
    assert found, "make setup should have installed karellen-llvm-core"
    assert all((llvm._major(p) or 0) >= 16 for p in found)


def test_old_system_llvms_are_never_candidates(monkeypatch, tmp_path):
    assert llvm._major(Path("/usr/lib/llvm-14/lib/libLLVM-14.so")) == 14
    assert llvm._major(Path("/venv/lib/libLLVM.so.23.1")) == 23
