"""Bad way-points: one InputError naming the offending index and the reason."""

from __future__ import annotations

import numpy as np
import pytest

from pf_offboard.errors import InputError
from pf_offboard.path import Path

GOOD = [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 1.5], [0.0, 1.0, 2.0], [-1.0, 0.5, 1.5]]


def _err(points, **kw) -> InputError:
    with pytest.raises(InputError) as exc:
        Path.from_waypoints(points, **kw)
    return exc.value


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("closed", [False, True])
def test_non_finite_names_the_index(bad, closed):
    pts = [list(p) for p in GOOD]
    pts[3][1] = bad
    e = _err(pts, closed=closed)
    assert e.field == "waypoints[3]"
    assert "finite" in e.reason


@pytest.mark.parametrize("closed", [False, True])
def test_consecutive_duplicate_names_the_index(closed):
    pts = GOOD[:3] + [GOOD[2]] + GOOD[3:]
    e = _err(pts, closed=closed)
    assert e.field == "waypoints[3]"
    assert "waypoints[2]" in e.reason


def test_closed_path_must_not_repeat_the_first_point():
    e = _err(GOOD + [GOOD[0]], closed=True)
    assert e.field == f"waypoints[{len(GOOD)}]"
    assert "do not repeat the first point" in e.reason
    # The same list is a fine open path that happens to end where it started.
    assert not Path.from_waypoints(GOOD + [GOOD[0]], closed=False).closed


def test_too_few_points():
    assert "at least 2" in _err([[0, 0, 0]]).reason
    assert "at least 3" in _err([[0, 0, 0], [1, 0, 0]], closed=True).reason
    # Four entries but only two distinct points, alternating: not a closed curve.
    e = _err([[0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]], closed=True)
    assert e.field == "waypoints" and "distinct" in e.reason


@pytest.mark.parametrize(
    "points",
    [[[0, 0], [1, 1]], [1.0, 2.0, 3.0], [[0, 0, 0], [1, 0]], [["a", 0, 0], [1, 0, 0]], []],
)
def test_malformed_arrays(points):
    e = _err(points)
    assert e.field == "waypoints"


def test_non_consecutive_repeats_are_allowed():
    pts = [[0, 0, 2], [1, -1, 2], [2, 0, 2], [1, 1, 2], [0, 0, 2], [-1, -1, 2], [-2, 0, 2], [-1, 1, 2]]
    path = Path.from_waypoints(pts, closed=True)
    assert path.closed and len(path.waypoints) == 8


def test_a_spline_that_stops_is_rejected():
    # Way-points doubling straight back on a closed path make the spline (almost) stop.
    e = _err([[0, 0, 0], [1, 0, 0], [2, 0, 0]], closed=True)
    assert e.field == "waypoints"


def test_waypoints_are_copied():
    pts = np.array(GOOD)
    path = Path.from_waypoints(pts)
    pts[0, 0] = 99.0
    assert path.waypoints[0, 0] == 0.0
    with pytest.raises(ValueError):
        path.waypoints[0, 0] = 1.0  # read-only


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("big", [1e300, -6000.0])
def test_absurd_coordinates_name_the_index(big, closed):
    """Finite but absurd (wrong units): refused before the spline fit (which would fail with an
    unnamed error or build a sampled path of millions of points)."""
    pts = [list(p) for p in GOOD]
    pts[2][1] = big
    e = _err(pts, closed=closed)
    assert e.field == "waypoints[2]" and "units" in e.reason


def test_a_5_km_path_is_accepted():
    path = Path.from_waypoints([[0.0, 0.0, 1.0], [4000.0, 0.0, 1.0], [4000.0, 5000.0, 50.0]])
    assert path.length_m > 6000.0


@pytest.mark.parametrize("closed", ["yes", 1, None])
def test_closed_must_be_a_bool(closed):
    e = _err(GOOD, closed=closed)
    assert e.field == "closed" and "true or false" in e.reason
