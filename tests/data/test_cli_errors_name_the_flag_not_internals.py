"""A value the build command refuses is reported in the user's terms: one ``error: ...`` line that names the real flag
(`--rt.max-depth`, `--coverage-samples`), how to fix it, exit status 2, through the CLI's error boundary; never
tyro's box with its internal name of the config (``Error parsing __tyro-dummy-inner__.rt``, ``Error parsing
BuildConfig``). tyro's own usage errors (a word where a number is expected) still name the flag, and --help works;
from Python, a value of the wrong type names its flag too instead of failing in a comparison."""

import numpy as np
import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.rt.settings import RTSettings

INTERNALS = ("__tyro", "dummy", "BuildConfig", "RTSettings", "Error parsing", "Traceback", "unexpected")


@pytest.fixture()
def no_tracing(monkeypatch):
    def traced(*args, **kwargs):
        raise AssertionError("the ray tracer was called for a setting that should have been refused first")

    monkeypatch.setattr(tracing, "trace_grid", traced)
    monkeypatch.setattr(static_build, "RayTracer", traced)


CHECKED = [  # refused by a config's own check (RTSettings, BuildConfig) while tyro builds it
    (["--rt.max-depth", "-1"], "--rt.max-depth"),
    (["--rt.max-depth", "11"], "--rt.max-depth"),
    (["--rt.frequency-hz", "1"], "--rt.frequency-hz"),
    (["--rt.samples-per-src", "0"], "--rt.samples-per-src"),
    (["--rt.batch-size", "-3"], "--rt.batch-size"),
    (["--rt.seed", "-1"], "--rt.seed"),
    (["--rt.rx-pattern", "isotropic"], "--rt.rx-pattern"),
    (["--rt.rx-polarization", "X"], "--rt.rx-polarization"),
    (["--coverage-samples", "0"], "--coverage-samples"),
    (["--retrace-radius-m", "0.5"], "--retrace-radius-m"),
    (["--tx-pose-error", "1", "95"], "--tx-pose-error"),
    (["--rt.frequency-hz", "nan"], "--rt.frequency-hz"),
    (["--tx-pose-error", "nan", "1"], "--tx-pose-error"),
]


@pytest.mark.parametrize("argv, flag", CHECKED, ids=[" ".join(a) for a, _ in CHECKED])
def test_a_refused_setting_is_one_error_line_naming_its_flag(root, no_tracing, capsys, argv, flag):
    assert cli.main(["build", "--scene", "cubicle", *argv]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and flag in first, err
    assert "how to fix:" in err and not any(word in err for word in INTERNALS), err
    assert not root.exists()


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--rt.max-depth", "x"], "--rt.max-depth"),
        (["--rt.frequency-hz", "abc"], "--rt.frequency-hz"),
        (["--coverage-samples", "1.5"], "--coverage-samples"),
    ],
)
def test_a_word_where_a_number_is_expected_is_a_usage_error_naming_its_flag(root, no_tracing, capsys, argv, flag):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["build", "--scene", "cubicle", *argv])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert flag in err and "__tyro" not in err
    assert not root.exists()


def test_help_still_prints_and_exits_0(root, capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["build", "--help"])
    assert exit_.value.code == 0
    assert "--rt.max-depth" in capsys.readouterr().out


@pytest.mark.parametrize(
    "changes, flag",
    [
        ({"max_depth": "3"}, "--rt.max-depth"),
        ({"frequency_hz": "2.4e9"}, "--rt.frequency-hz"),
        ({"seed": 1.5}, "--rt.seed"),
        ({"samples_per_src": None}, "--rt.samples-per-src"),
        ({"los": 1}, "--rt.los"),
        ({"rx_pattern": 3}, "--rt.rx-pattern"),
    ],
)
def test_a_value_of_the_wrong_type_from_python_names_its_flag_instead_of_a_type_error(changes, flag):
    with pytest.raises(InvalidSettingError, match=flag.replace(".", r"\.")):
        RTSettings(**changes)


def test_equal_numbers_of_other_types_make_equal_settings():
    assert RTSettings(frequency_hz=2_400_000_000, max_depth=np.int64(5)).hashed() == RTSettings().hashed()
