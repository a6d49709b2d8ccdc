"""Moving frames: Frenet-Serret and rotation-minimising; exact derivatives; auto choice."""

from __future__ import annotations

import numpy as np
import pytest
from pathtools import config_waypoints, rel_err

from pf_offboard.errors import InputError
from pf_offboard.path import Path

VECS = (("t", "dt", "ddt"), ("e2", "de2", "dde2"), ("e3", "de3", "dde3"))


def _check_orthonormal(f) -> None:
    m = np.array([f.t, f.e2, f.e3])
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(np.cross(f.t, f.e2), f.e3, atol=1e-12)  # right-handed


def _check_derivatives(path: Path, lams, h: float = 1e-5, tol: float = 1e-6) -> None:
    for lam in lams:
        f, fp, fm = path.frame(lam), path.frame(lam + h), path.frame(lam - h)
        _check_orthonormal(f)
        for v, dv, ddv in VECS:
            assert rel_err((getattr(fp, v) - getattr(fm, v)) / (2 * h), getattr(f, dv)) < tol, (lam, dv)
            assert rel_err((getattr(fp, dv) - getattr(fm, dv)) / (2 * h), getattr(f, ddv)) < tol, (lam, ddv)
        # Derivatives of orthonormality: <t, t'> = 0 and <e2', t> = -<e2, t'> (a consequence only
        # if the derivatives belong to the frame returned).
        assert abs(np.dot(f.t, f.dt)) < 1e-12
        assert abs(np.dot(f.de2, f.t) + np.dot(f.e2, f.dt)) < 1e-12


@pytest.mark.parametrize("name", ["paper", "helix"])
def test_frenet_frame(name, request):
    path = request.getfixturevalue(name)
    assert path.frame_kind == "frenet"
    lams = np.random.default_rng(4).uniform(0, path.lam_max, 40)
    _check_derivatives(path, lams)
    for lam in lams[:10]:
        f, p = path.frame(lam), path.eval(lam)
        speed = np.linalg.norm(p.d1)
        kappa = path.curvature(lam)
        # Eq. (8): t' = |sigma'| kappa p, p' = |sigma'| (-kappa t + tau b), b' = -|sigma'| tau p.
        np.testing.assert_allclose(f.dt, speed * kappa * f.e2, atol=1e-12)
        c12 = np.cross(p.d1, p.d2)
        tau = np.dot(c12, p.d3) / np.dot(c12, c12)
        np.testing.assert_allclose(f.de2, speed * (-kappa * f.t + tau * f.e3), atol=1e-10)
        np.testing.assert_allclose(f.de3, -speed * tau * f.e2, atol=1e-10)
        # p points towards the centre of curvature: same side as sigma''.
        assert np.dot(f.e2, p.d2) > 0


def test_frenet_of_a_circle_is_known():
    th = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    r = 2.0
    path = Path.from_waypoints(np.c_[r * np.cos(th), r * np.sin(th), np.full_like(th, 1.5)], closed=True)
    assert path.frame_kind == "frenet"
    for lam in np.linspace(0, path.lam_max, 17):
        f, p = path.frame(lam), path.eval(lam).sigma
        radial = np.array([p[0], p[1], 0.0]) / np.hypot(p[0], p[1])
        np.testing.assert_allclose(f.e2, -radial, atol=2e-4)  # normal points to the centre
        np.testing.assert_allclose(f.e3, [0, 0, 1], atol=2e-4)  # counter-clockwise: binormal up
        assert path.curvature(lam) == pytest.approx(1 / r, rel=1e-3)


@pytest.mark.parametrize("name", ["paper_rmf", "figure8", "helix_rmf", "racetrack", "straight"])
def test_rmf_derivatives_and_orthonormality(name, request):
    path = request.getfixturevalue(name)
    assert path.frame_kind == "rmf"
    lams = np.random.default_rng(5).uniform(0, path.lam_max, 40)
    _check_derivatives(path, lams)


@pytest.mark.parametrize("name", ["paper_rmf", "figure8", "helix_rmf", "racetrack"])
def test_rmf_is_rotation_minimising(name, request):
    path = request.getfixturevalue(name)
    rate = path._rmf.twist_rate
    if not path.closed:
        assert rate == 0.0
    else:
        assert rate == pytest.approx(-path._rmf.holonomy_rad / path.lam_max)
    for lam in np.linspace(0, path.lam_max, 300):
        f = path.frame(lam)
        # Parallel transport: the normals do not rotate about t beyond the distributed closing twist.
        assert abs(np.dot(f.de2, f.e3) - rate) < 1e-6
        assert abs(np.dot(f.de3, f.e2) + rate) < 1e-6


def test_rmf_twist_is_nonzero_on_a_non_planar_loop(paper_rmf, figure8):
    # A non-planar closed curve has holonomy: the test above must be checking something.
    assert abs(paper_rmf._rmf.holonomy_rad) > 1e-3
    # A planar loop's transported frame returns to itself (no twist needed).
    assert abs(figure8._rmf.holonomy_rad) < 1e-9


def test_rmf_follows_frenet_up_to_a_constant_angle_where_torsion_is_zero():
    # Planar curve with kappa > 0: FS is parallel-transported too, so RMF = FS rotated by a constant.
    th = np.linspace(0, np.pi, 12)
    pts = np.c_[2 * np.cos(th), 1.2 * np.sin(th), np.full_like(th, 2.0)]
    fs, rm = Path.from_waypoints(pts, frame="frenet"), Path.from_waypoints(pts, frame="rmf")
    angles = []
    for lam in np.linspace(0.5, fs.lam_max - 0.5, 25):
        a, b = fs.frame(lam), rm.frame(lam)
        angles.append(np.arctan2(np.dot(b.e2, a.e3), np.dot(b.e2, a.e2)))
    assert np.ptp(angles) < 1e-6


@pytest.mark.parametrize("name", ["paper_rmf", "figure8", "racetrack"])
def test_rmf_closes_smoothly(name, request):
    path = request.getfixturevalue(name)
    a, b = path.frame(path.lam_max - 1e-9), path.frame(1e-9)
    for field in a._fields:
        assert rel_err(getattr(a, field), getattr(b, field)) < 1e-6, field
    # And derivatives across the seam agree with finite differences through it.
    _check_derivatives(path, [0.0, 1e-6, path.lam_max - 1e-6])


def test_frenet_closes_smoothly(paper):
    a, b = paper.frame(paper.lam_max - 1e-9), paper.frame(1e-9)
    for field in a._fields:
        assert rel_err(getattr(a, field), getattr(b, field)) < 1e-6, field


def test_straight_path_frame_is_constant(straight):
    f0 = straight.frame(0.0)
    for lam in np.linspace(0, straight.lam_max, 20):
        f = straight.frame(lam)
        for v, dv, ddv in VECS:
            np.testing.assert_allclose(getattr(f, v), getattr(f0, v), atol=1e-12)
            np.testing.assert_allclose(getattr(f, dv), 0.0, atol=1e-12)
            np.testing.assert_allclose(getattr(f, ddv), 0.0, atol=1e-12)
    # Initial normal convention: e3 is world-up made orthogonal to t (e3_z > 0), e2 = e3 x t.
    assert f0.e3[2] > 0 and abs(np.dot(f0.e3, f0.t)) < 1e-12


def test_auto_choice(paper, helix, figure8, straight, racetrack):
    assert paper.frame_kind == "frenet"  # kappa in [0.49, 1.04] 1/m
    assert helix.frame_kind == "frenet"
    assert figure8.frame_kind == "rmf"  # planar with inflections
    assert racetrack.frame_kind == "rmf"
    pts, closed, _ = config_waypoints("straight.yaml")
    assert Path.from_waypoints(pts, closed=closed, frame="auto").frame_kind == "rmf"


@pytest.mark.parametrize("name", ["straight.yaml", "figure8.yaml"])
def test_forced_frenet_on_zero_curvature_is_an_error(name):
    pts, closed, _ = config_waypoints(name)
    with pytest.raises(InputError) as exc:
        Path.from_waypoints(pts, closed=closed, frame="frenet")
    assert exc.value.field == "path.moving_frame"
    assert "curvature" in exc.value.reason


def test_unknown_frame_kind_is_an_error():
    with pytest.raises(InputError) as exc:
        Path.from_waypoints([[0, 0, 0], [1, 0, 0]], frame="bishop")
    assert exc.value.field == "path.moving_frame"


def test_curvature_matches_frame(paper_rmf):
    for lam in np.linspace(0, paper_rmf.lam_max, 30):
        p = paper_rmf.eval(lam)
        kappa = np.linalg.norm(np.cross(p.d1, p.d2)) / np.linalg.norm(p.d1) ** 3
        assert paper_rmf.curvature(lam) == pytest.approx(kappa, rel=1e-12)
        # For any frame: |t'| = |sigma'| kappa.
        f = paper_rmf.frame(lam)
        assert np.linalg.norm(f.dt) == pytest.approx(np.linalg.norm(p.d1) * kappa, rel=1e-10)


def test_frame_returns_fresh_equal_values(paper):
    a = paper.frame(1.0)
    b = paper.frame(1.0)
    c = paper.frame(1.0 + 1e-3)
    np.testing.assert_array_equal(a.t, b.t)
    assert not np.array_equal(a.t, c.t)
    with pytest.raises(ValueError):
        a.e2[0] = 1.0  # cached frames are read-only


def test_float_forms_match_array_forms(paper_rmf):
    for lam in (0.0, 1.7, paper_rmf.lam_max - 1e-3, paper_rmf.lam_max + 1.7):
        p = paper_rmf.eval(lam)
        np.testing.assert_array_equal(np.array(paper_rmf.eval_floats(lam)).reshape(5, 3), np.array(p))
        (t, t1, t2), (e, e1, e2), (b, b1, b2) = paper_rmf.frame_jets(lam)
        f = paper_rmf.frame(lam)
        np.testing.assert_array_equal(np.array([t, e, b, t1, e1, b1, t2, e2, b2]), np.array(f))


@pytest.mark.parametrize("name", ["paper_rmf", "helix_rmf"])
def test_rmf_is_c2_across_its_interpolation_nodes(name, request):
    # e2 between nodes is a Hermite interpolant: value, first and second derivative must match
    # from both sides of every node (the control law differentiates them).
    path = request.getfixturevalue(name)
    nodes = np.array(path._rmf._nodes[1:-1])
    for node in nodes[:: max(1, len(nodes) // 40)]:
        a, b = path.frame(node - 1e-9), path.frame(node + 1e-9)
        for field in a._fields:
            assert rel_err(getattr(a, field), getattr(b, field)) < 1e-6, (node, field)


def test_rmf_matches_an_independent_parallel_transport_integration(helix_rmf):
    # Integrate e' = -<e, t'> t with an adaptive ODE solver from the same start vector and
    # compare along the open helix (no closing twist on open paths).
    from scipy.integrate import solve_ivp

    def rhs(lam, e):
        f = helix_rmf.frame(lam)
        return -np.dot(e, f.dt) * f.t

    e0 = helix_rmf.frame(0.0).e2
    lams = np.linspace(0.0, helix_rmf.lam_max, 25)
    sol = solve_ivp(rhs, (0.0, helix_rmf.lam_max), e0, t_eval=lams, rtol=1e-11, atol=1e-12, method="DOP853")
    for lam, e_ref in zip(sol.t, sol.y.T):
        assert np.linalg.norm(helix_rmf.frame(lam).e2 - e_ref / np.linalg.norm(e_ref)) < 1e-7, lam


@pytest.mark.parametrize("radius, kind", [(8.0, "frenet"), (12.0, "rmf")])
def test_auto_threshold_is_the_documented_one(radius, kind):
    # A circle has constant curvature 1/r: frenet iff 1/r >= 0.1 1/m (AUTO_FRENET_MIN_KAPPA_1_M).
    th = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    pts = np.c_[radius * np.cos(th), radius * np.sin(th), np.zeros_like(th)]
    assert Path.from_waypoints(pts, closed=True).frame_kind == kind
    # Both can be forced (the curvature is far from zero).
    assert Path.from_waypoints(pts, closed=True, frame="frenet").frame_kind == "frenet"
    assert Path.from_waypoints(pts, closed=True, frame="rmf").frame_kind == "rmf"
