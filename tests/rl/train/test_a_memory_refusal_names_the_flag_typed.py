"""A memory setting that does not fit is refused naming the flag the user typed; a setting the preset gave is named
as the preset's, with the flags that turn the memory off (which then validate)."""

import shlex

import pytest

from dtradar_rl.cli import main
from dtradar_rl.train.config import DQNConfig, config_for

TRAIN = ["train", "--scene", "synthetic-8x6", "--variant", "moving"]


def refusal(capsys, *typed: str) -> str:
    assert main([*TRAIN, *typed]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "Traceback" not in err
    return err


def fix_flags(err: str, after: str) -> dict:
    """The settings of the flags the hint names after ``after``, as DQNConfig fields."""
    flags = shlex.split(err.split(after, 1)[1].split(",")[0].split(";")[0])
    values = {"--memory-radius": ("memory_radius", int), "--escape-after": ("escape_after", int)}
    kw, args = {}, iter(flags)
    for f in args:
        if f in values:
            name, cast = values[f]
            kw[name] = cast(next(args))
        else:
            kw[f.removeprefix("--no-").replace("-", "_")] = False
    return kw


def test_obs_goal_names_what_was_typed_and_the_memory_as_the_presets_default(capsys):
    err = refusal(capsys, "--obs", "goal")
    assert err.startswith("error: --obs goal does not fit the memory-escape-noise-margin preset's memory, which is on")
    assert "the preset sets it to 5" in err
    assert "how to fix: keep --obs neighbors, or turn the memory off: add --memory-radius 0 --no-memory-visits" in err
    DQNConfig(obs="goal", **fix_flags(err, "turn the memory off: add ")).validate()  # the hint's flags fit
    assert main([*TRAIN, "--obs", "goal", "--preset", "tuned", "--total-env-steps", "-1"]) == 2
    assert "--obs" not in capsys.readouterr().err  # --preset tuned has no memory: only the budget is refused


def test_memory_radius_zero_names_itself_and_the_presets_maps(capsys):
    err = refusal(capsys, "--memory-radius", "0")
    assert "error: --memory-radius 0 turns the memory window off, and the memory-escape-noise-margin preset's" in err
    assert "--memory-visits (on by default) are maps of it" in err
    assert "turn the whole memory off: --no-memory-visits --escape-after 0" in err
    DQNConfig(memory_radius=0, **fix_flags(err, "turn the whole memory off: ")).validate()


def test_no_memory_visits_names_itself_and_the_presets_loop_escape(capsys):
    err = refusal(capsys, "--no-memory-visits")
    assert "error: --no-memory-visits: the memory-escape-noise-margin preset's loop escape (--escape-after 2" in err
    assert "how to fix: add --escape-after 0 too" in err


@pytest.mark.parametrize(
    ("typed", "message"),
    [
        ({"obs": "goal", "memory_radius": 3}, "--memory-radius needs --obs neighbors"),
        ({"escape_after": 3, "memory_visits": False}, "--escape-after reads the memory's visit counts"),
        ({"memory_radius": 0, "memory_bumps": True}, "--memory-bumps and --memory-visits are maps"),
    ],
)
def test_flags_typed_together_that_do_not_fit_are_named_together(typed, message):
    with pytest.raises(ValueError, match=message):
        config_for(**typed)
