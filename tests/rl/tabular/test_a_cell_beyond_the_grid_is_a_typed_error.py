"""``TabularMDP.states`` of a cell number outside the grid (pairs taken from another scene's twin, a negative number)
is an :class:`InvalidCoordinatesError` naming the cell and the grid, not a raw IndexError (beyond the grid) or the
state of another cell (a negative number counted from the end)."""

import numpy as np
import pytest

from dtradar_data.core.errors import InvalidCoordinatesError
from dtradar_rl.tabular.solver import TabularMDP, solve
from dtradar_rl.task.grid_mdp import GridMDP


@pytest.fixture()
def tab() -> TabularMDP:
    return TabularMDP.from_mdp(GridMDP.from_blocked(np.zeros((3, 4), bool), name="tiny/blueprint"))


@pytest.mark.parametrize("cell", [12, 1000, -1])
def test_a_cell_outside_the_grid_is_a_typed_error_naming_the_cell_and_the_grid(tab, cell):
    with pytest.raises(InvalidCoordinatesError) as e:
        tab.states(np.array([0, 5, cell]))
    assert f"cell {cell} is outside" in e.value.message and "4 x 3 grid" in e.value.message, e.value.message
    assert "tiny/blueprint" in e.value.message and e.value.hint
    assert not isinstance(e.value, IndexError)


def test_a_target_outside_the_grid_is_refused_by_the_solver_too(tab):
    with pytest.raises(InvalidCoordinatesError, match="cell 99 is outside"):
        solve(tab, "geodesic", 0.9, [99])
    np.testing.assert_array_equal(tab.states(np.array([[0, 11]])), [[0, 11]])  # in-grid cells unchanged, any shape
