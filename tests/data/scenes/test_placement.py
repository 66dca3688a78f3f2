"""Greedy line-of-sight transmitter sites: each sees the most cells no earlier site sees; walls stop the view."""

import numpy as np

from dtradar_data.scenes.placement import place_sites, visibility


def two_rooms() -> np.ndarray:
    """A 9 x 4 plan with a wall down column 4 (two 4 x 4 rooms that cannot see each other)."""
    blocked = np.zeros((4, 9), bool)
    blocked[:, 4] = True
    return blocked


def test_a_wall_stops_the_view_and_the_range_limits_it():
    b = two_rooms()
    seen = visibility(b, np.array([0]), range_cells=20).reshape(4, 9)
    assert seen[:, :4].all() and not seen[:, 4:].any()
    short = visibility(b, np.array([0]), range_cells=1.2).reshape(4, 9)
    assert short[0, 1] and not short[3, 3]


def test_two_rooms_take_one_site_each_and_are_then_covered():
    sites, share = place_sites(two_rooms(), range_cells=20, clearance_cells=0)
    assert len(sites) == 2 and share == 1.0
    assert {s % 9 < 4 for s in sites} == {True, False}  # one in each room


def test_cells_already_covered_send_the_next_site_elsewhere_and_a_kept_site_stays_first():
    b = two_rooms()
    covered = np.zeros_like(b)
    covered[:, :4] = True  # the left room hears a transmitter already
    (site,), share = place_sites(b, range_cells=20, clearance_cells=0, covered=covered, max_sites=1)
    assert site % 9 > 4 and share == 1.0
    sites, _ = place_sites(b, range_cells=20, clearance_cells=0, start=(0,))
    assert sites[0] == 0 and len(sites) == 2
