"""``python -m dtradar_rl log --help`` speaks of logging, not training: the shared options say what they do for a
log (the medium agent's network, the device the robots step on), ``--out`` (a log goes into the store) is not offered,
and no option states its default twice."""

import re

import pytest

from dtradar_rl.cli import main


def _help(capsys, command: str) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    return " ".join(capsys.readouterr().out.replace("│", " ").split())  # the box and the line wrapping removed


def test_log_help_names_logging_and_what_the_network_and_device_options_size(capsys):
    text = _help(capsys, "log")
    assert "to train on" not in text
    assert "scene to log on" in text and "twin to log on" in text
    assert "--out" not in text, "a log is stored under its name; --out did nothing"
    hidden = text.partition("--hidden")[2].partition("--device")[0]
    assert "medium agent" in hidden
    device = text.partition("--device")[2].partition("--behaviour")[0]
    assert "logging" in device and "medium agent" in device


@pytest.mark.parametrize("command", ["log", "offline", "train"])
def test_no_option_states_its_default_twice(capsys, command):
    text = _help(capsys, command)
    twice = re.findall(r"\(default[: ][^)]*\) \(default: [^)]*\)", text)
    assert not twice, twice
    # an empty default that the help text explains ("default: the newest") is not shown again as '' or None
    for option in re.split(r" (?=--[a-z])", text):
        hint = re.search(r"\(default: (''|None)\)$", option)
        assert not (hint and "default" in option[: hint.start()]), option


def test_log_refuses_out_as_an_unknown_option(root, capsys):
    # in an empty data root: were --out accepted, the log would stop at the missing twin, never write a dataset
    with pytest.raises(SystemExit) as exit_info:
        main(["log", "--out", "somewhere"])
    assert exit_info.value.code != 0
    assert "--out" in capsys.readouterr().err
