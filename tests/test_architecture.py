"""The architecture contracts in pyproject.toml ([tool.importlinter]) hold: layers, no torch in dtradar_data, only
dtradar_data.rt imports the ray tracer, dtradar_rl never imports it."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_import_contract_is_kept():
    exe = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    run = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml")], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
    assert "0 broken" in run.stdout


#: What dtradar_rl may import from dtradar_data (the public surface named in ``dtradar_data.__init__``): packages
#: whose ``__init__`` exports what a consumer needs, every module of core, and two single modules.
SURFACE_PACKAGES = ("dtradar_data", "dtradar_data.store", "dtradar_data.store.logged", "dtradar_data.scenes")
SURFACE_MODULES = ("dtradar_data.rt.settings", "dtradar_data.geometry.floorplan")


def on_surface(module: str) -> bool:
    return module in SURFACE_PACKAGES or module in SURFACE_MODULES or module.startswith("dtradar_data.core.")


def test_the_surface_rule_takes_core_and_the_named_packages_and_nothing_below_them():
    assert on_surface("dtradar_data.core.errors") and on_surface("dtradar_data.store.logged")
    assert not on_surface("dtradar_data.store.local") and not on_surface("dtradar_data.pipeline.synthetic")


def test_dtradar_rl_reaches_dtradar_data_only_through_its_public_surface():
    import grimp  # comes with import-linter (the dev extra)

    graph = grimp.build_graph("dtradar_rl", "dtradar_data", cache_dir=None)
    off = sorted(
        (m, i)
        for m in graph.modules
        if m.startswith("dtradar_rl")
        for i in graph.find_modules_directly_imported_by(m)
        if i.startswith("dtradar_data") and not on_surface(i)
    )
    assert not off, "dtradar_rl imports dtradar_data outside its public surface: " + "; ".join(
        f"{m} -> {i}" for m, i in off
    )
