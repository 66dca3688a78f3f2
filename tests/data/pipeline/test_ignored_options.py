"""No build option is silently ignored: an option that would change nothing in what is built is refused with what to
do instead, before anything is traced or written (no ray tracer: tracing is made to fail the test)."""

import pytest

from dtradar_data.cli import main
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.pipeline import static_build, tracing
from dtradar_data.pipeline.builder import build
from dtradar_data.pipeline.config import BuildConfig


@pytest.fixture(autouse=True)
def no_tracing(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the build traced although it should have been refused first")

    monkeypatch.setattr(static_build, "RayTracer", refuse)
    monkeypatch.setattr(tracing, "trace_grid", refuse)


@pytest.mark.parametrize(
    ("options", "flag"),
    [
        (dict(variant="blueprint", differential=True), "--differential"),
        (dict(retrace_radius_m=2.0), "--retrace-radius-m"),
        (dict(variant="dynamic", differential=True, executor="ray"), "--executor ray"),
    ],
)
def test_an_option_that_would_change_nothing_is_refused_naming_it(options, flag):
    with pytest.raises(InvalidSettingError) as err:
        BuildConfig(scene="cubicle", **options)
    assert flag in err.value.message and err.value.hint


def exit_status(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # tyro reports an error in a config's __post_init__ as a usage error
        return int(exc.code)


def test_differential_with_the_blueprint_variant_exits_2_from_the_command_line_and_writes_nothing(root, capsys):
    assert exit_status(["build", "--scene", "cubicle", "--variant", "blueprint", "--differential"]) == 2
    assert "--differential applies to dynamic twins only" in capsys.readouterr().err
    assert not root.exists()


def test_differential_on_a_scene_without_a_dynamic_twin_is_refused_before_its_blueprint_is_traced(root):
    with pytest.raises(InvalidSettingError, match="has none to build"):
        build(BuildConfig(scene="dallas-q1", differential=True, progress=False))  # a quadrant without dynamic twin
    assert not root.exists()


def test_the_help_says_what_differential_does_with_each_variant(capsys):
    with pytest.raises(SystemExit):
        main(["build", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "With --variant all the blueprint is traced in full first" in text
    assert "--variant blueprint is refused" in text
    assert "A --differential re-trace always runs in this process" in text
