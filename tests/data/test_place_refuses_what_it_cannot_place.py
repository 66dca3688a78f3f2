"""``python -m dtradar_data place`` refuses an option it cannot place sites with, naming its flag: one ``error: ...``
line, how to fix it, exit status 2. A share of the free cells outside (0, 1], no site at all, a range of zero or
below, a negative clearance are refused when parsed, before the scene is read (they used to print 4 sites, or none,
with exit status 0, or fail with an internal ValueError); a clearance no free cell of the scene has is refused once
the plan is known; ``--heard-in`` takes a ray-traced twin, not a logged offline-RL dataset (it used to fail with an
internal AttributeError)."""

import numpy as np
import pytest

from dtradar_data import cli
from dtradar_data.core.errors import InvalidSettingError
from dtradar_data.scenes import placement
from dtradar_data.scenes.placement import place_sites

INTERNALS = ("Traceback", "unexpected", "ValueError", "AttributeError", "__tyro", "Error parsing")


@pytest.fixture()
def nothing_placed(monkeypatch):
    def placed(*args, **kwargs):
        raise AssertionError("sites were placed for an option that should have been refused first")

    monkeypatch.setattr(placement, "place_sites", placed)


def refused(capsys, argv: list[str], flag: str) -> str:
    assert cli.main(["place", "cubicle", *argv]) == 2
    err = capsys.readouterr().err
    first = err.splitlines()[0]
    assert first.startswith("error: ") and flag in first, err
    assert "how to fix:" in err and not any(word in err for word in INTERNALS), err
    return err


OUT_OF_RANGE = [
    (["--coverage", "1.5"], "--coverage"),
    (["--coverage", "-0.1"], "--coverage"),
    (["--coverage", "0"], "--coverage"),
    (["--max-sites", "0"], "--max-sites"),
    (["--max-sites", "-2"], "--max-sites"),
    (["--range-m", "-5"], "--range-m"),
    (["--range-m", "0"], "--range-m"),
    (["--clearance-cells", "-1"], "--clearance-cells"),
]


@pytest.mark.parametrize("argv, flag", OUT_OF_RANGE, ids=[" ".join(a) for a, _ in OUT_OF_RANGE])
def test_an_option_out_of_range_is_refused_when_parsed_naming_its_flag(root, nothing_placed, capsys, argv, flag):
    refused(capsys, argv, flag)


def test_a_clearance_no_free_cell_has_is_refused_naming_the_flag_and_the_widest_there_is(root, capsys):
    err = refused(capsys, ["--clearance-cells", "100"], "--clearance-cells")
    assert "at most" in err


def test_place_sites_names_the_widest_clearance_the_plan_has():
    blocked = np.ones((7, 9), bool)
    blocked[1:6, 1:8] = False  # a 7 x 5 room: its middle row's cells 3 to 5 have 2 free cells all around them
    sites, share = place_sites(blocked, range_cells=20, clearance_cells=2)
    assert sites == [3 * 9 + 3] and share == 1.0
    with pytest.raises(InvalidSettingError, match="--clearance-cells 3") as e:
        place_sites(blocked, range_cells=20, clearance_cells=3)
    assert "--clearance-cells 2" in str(e.value)
    with pytest.raises(InvalidSettingError, match="no free cell"):
        place_sites(np.ones((3, 3), bool), range_cells=20, clearance_cells=0)


@pytest.mark.parametrize("name", ["cubicle/blueprint/expert", "cubicle/blueprint/expert@v0", ""])
def test_heard_in_takes_a_twin_not_a_logged_dataset(root, nothing_placed, capsys, name):
    err = refused(capsys, ["--heard-in", name], "--heard-in")
    assert "<scene>/<variant>" in err
