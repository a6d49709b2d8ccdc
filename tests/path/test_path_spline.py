"""Quintic spline: interpolation, C4 continuity (knots and closed seam), derivatives, arclength."""

from __future__ import annotations

import numpy as np
import pytest
from pathtools import rel_err
from scipy.integrate import quad

from pf_offboard.path import Path

ORDERS = ("sigma", "d1", "d2", "d3", "d4")


def _knots(path: Path) -> np.ndarray:
    return path._spline.knots


@pytest.mark.parametrize("name", ["paper", "figure8", "helix", "straight", "racetrack"])
def test_hits_waypoints(name, request):
    path = request.getfixturevalue(name)
    for k, w in zip(_knots(path), path.waypoints):
        np.testing.assert_allclose(path.eval(k).sigma, w, atol=1e-12)


def test_chord_length_parametrisation(paper, helix):
    for path in (paper, helix):
        speeds = [np.linalg.norm(path.eval(lam).d1) for lam in np.linspace(0, path.lam_max, 400)]
        # |sigma'| ~ 1 (exactly 1 would be arclength); it must be bounded well away from 0.
        assert 0.9 < min(speeds) <= 1.0 <= max(speeds) < 1.3


@pytest.mark.parametrize("name", ["paper", "figure8", "helix", "racetrack"])
def test_c4_continuity_at_knots(name, request):
    path = request.getfixturevalue(name)
    knots = list(_knots(path)[1:-1])
    if path.closed:
        knots.append(0.0)  # the seam: eval wraps, so -delta is just before lam_max
    delta = 1e-9
    for k in knots:
        left, right = path.eval(k - delta), path.eval(k + delta)
        for order in ORDERS:
            # A jump in a C4 derivative would be O(1); here only O(delta * sigma^(5)).
            assert rel_err(getattr(left, order), getattr(right, order)) < 1e-6, (k, order)


def test_seam_is_periodic(paper):
    a, b = paper.eval(paper.lam_max), paper.eval(0.0)
    c = paper.eval(paper.lam_max * 3 + 0.7)
    d = paper.eval(0.7)
    for order in ORDERS:
        assert rel_err(getattr(a, order), getattr(b, order)) < 1e-12
        assert rel_err(getattr(c, order), getattr(d, order)) < 1e-9


def test_fifth_derivative_does_jump_at_knots(paper):
    # The continuity check above resolves jumps: sigma^(5) (piecewise constant) does jump at knots.
    h = 1e-4
    jumps = []
    for k in _knots(paper)[1:-1]:
        left = (paper.eval(k - h).d4 - paper.eval(k - 2 * h).d4) / h
        right = (paper.eval(k + 2 * h).d4 - paper.eval(k + h).d4) / h
        jumps.append(np.max(np.abs(left - right)))
    assert max(jumps) > 1e-2


@pytest.mark.parametrize("name", ["paper", "helix", "figure8"])
def test_derivatives_match_finite_differences(name, request):
    path = request.getfixturevalue(name)
    rng = np.random.default_rng(1)
    h = 1e-5
    for lam in rng.uniform(0.0, path.lam_max, 40):
        p, pp, pm = path.eval(lam), path.eval(lam + h), path.eval(lam - h)
        for lo, hi in zip(ORDERS[:-1], ORDERS[1:]):
            fd = (getattr(pp, lo) - getattr(pm, lo)) / (2 * h)
            assert rel_err(fd, getattr(p, hi)) < 1e-6, (lam, hi)


def test_two_point_open_path_is_a_straight_segment():
    a, b = np.array([1.0, -2.0, 0.5]), np.array([4.0, 2.0, 0.5])
    path = Path.from_waypoints([a, b])
    assert path.lam_max == pytest.approx(5.0)
    assert path.length_m == pytest.approx(5.0, rel=1e-12)
    for lam in np.linspace(0, 5, 11):
        p = path.eval(lam)
        np.testing.assert_allclose(p.sigma, a + lam * (b - a) / 5.0, atol=1e-12)
        np.testing.assert_allclose(p.d1, (b - a) / 5.0, atol=1e-12)
        for order in ("d2", "d3", "d4"):
            np.testing.assert_allclose(getattr(p, order), 0.0, atol=1e-12)


def test_collinear_waypoints_give_the_straight_line(straight):
    a, b = straight.waypoints[0], straight.waypoints[-1]
    u = (b - a) / np.linalg.norm(b - a)
    for lam in np.linspace(0, straight.lam_max, 97):
        p = straight.eval(lam)
        off = (p.sigma - a) - np.dot(p.sigma - a, u) * u
        assert np.linalg.norm(off) < 1e-12
        assert straight.curvature(lam) < 1e-9
    assert straight.length_m == pytest.approx(np.linalg.norm(b - a), rel=1e-12)


def test_open_end_conditions_are_natural(helix):
    for lam in (0.0, helix.lam_max):
        p = helix.eval(lam)
        np.testing.assert_allclose(p.d3, 0.0, atol=1e-9)
        np.testing.assert_allclose(p.d4, 0.0, atol=1e-9)


def _speed(path: Path):
    return lambda lam: float(np.linalg.norm(path.eval(lam).d1))


@pytest.mark.parametrize("name", ["paper", "helix", "figure8"])
def test_arclength_matches_dense_quadrature(name, request):
    path = request.getfixturevalue(name)
    knots = _knots(path)
    # Reference: adaptive quadrature per spline segment (the integrand is smooth inside each).
    seg = [quad(_speed(path), a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0] for a, b in zip(knots[:-1], knots[1:])]
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    assert abs(path.length_m - cum[-1]) <= 1e-9 * cum[-1]
    rng = np.random.default_rng(2)
    for lam in rng.uniform(0, path.lam_max, 15):
        i = int(np.searchsorted(knots, lam, side="right") - 1)
        ref = cum[i] + quad(_speed(path), knots[i], lam, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        assert abs(path.arclength(lam) - ref) <= 1e-9 * path.length_m, lam
    # Strictly increasing and consistent with the speed.
    lam = 3.3
    h = 1e-5
    fd = (path.arclength(lam + h) - path.arclength(lam - h)) / (2 * h)
    assert fd == pytest.approx(_speed(path)(lam), rel=1e-8)


def test_arclength_detects_a_wrong_length():
    # Sanity of the reference: a quarter circle's arclength is known exactly (up to spline error).
    th = np.linspace(0, np.pi / 2, 40)
    path = Path.from_waypoints(np.c_[np.cos(th), np.sin(th), np.zeros_like(th)])
    assert path.length_m == pytest.approx(np.pi / 2, rel=1e-6)
    assert abs(path.length_m - np.pi / 2) > 0  # a spline, not the circle itself


@pytest.mark.parametrize("name", ["paper", "helix", "straight"])
def test_arclength_inverse_round_trip(name, request):
    path = request.getfixturevalue(name)
    rng = np.random.default_rng(3)
    for s in rng.uniform(0, path.length_m, 50):
        lam = path.lam_at_arclength(s)
        assert abs(path.arclength(lam) - s) <= 1e-9 * path.length_m
    for lam in rng.uniform(0, path.lam_max, 50):
        assert path.lam_at_arclength(path.arclength(lam)) == pytest.approx(lam, abs=1e-9 * path.lam_max)
    assert path.lam_at_arclength(0.0) == pytest.approx(0.0, abs=1e-12)


def test_arclength_inverse_wraps_and_clamps(paper, helix):
    L = paper.length_m
    assert paper.lam_at_arclength(L + 2.0) == pytest.approx(paper.lam_at_arclength(2.0), abs=1e-9)
    assert paper.lam_at_arclength(-1.0) == pytest.approx(paper.lam_at_arclength(L - 1.0), abs=1e-9)
    assert helix.lam_at_arclength(helix.length_m + 5.0) == helix.lam_max
    assert helix.lam_at_arclength(-5.0) == 0.0


def test_wrap(paper, helix):
    m = paper.lam_max
    assert paper.wrap(m) == 0.0
    assert paper.wrap(-1e-18) < m
    assert paper.wrap(m + 1.25) == pytest.approx(1.25)
    assert paper.wrap(-0.5) == pytest.approx(m - 0.5)
    assert helix.wrap(-0.5) == 0.0
    assert helix.wrap(helix.lam_max + 3.0) == helix.lam_max
    assert helix.wrap(2.0) == 2.0


def test_arclength_inverse_near_the_seam(paper):
    L = paper.length_m
    for s in (0.0, 1e-15, 1e-9, L - 1e-9, L - 1e-15, L, 2 * L):
        lam = paper.lam_at_arclength(s)
        assert 0.0 <= lam < paper.lam_max
        expect = s % L
        got = paper.arclength(lam)
        # s just below L maps to lam just below lam_max or (rounding) to 0: both are the seam.
        assert min(abs(got - expect), abs(abs(got - expect) - L)) < 1e-9


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
@pytest.mark.parametrize("name", ["paper", "helix"])
def test_non_finite_parameter_is_an_error_not_nan(name, bad, request):
    """Every query by lambda (or arclength) refuses NaN/inf with an InputError naming it."""
    from pf_offboard.errors import InputError

    path = request.getfixturevalue(name)
    for query in (path.eval, path.eval_floats, path.frame, path.curvature, path.arclength, path.wrap):
        with pytest.raises(InputError, match="lam"):
            query(bad)
    with pytest.raises(InputError, match="s_m"):
        path.lam_at_arclength(bad)
