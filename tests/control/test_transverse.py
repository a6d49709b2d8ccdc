"""Exact transverse coordinates: T(x)'s time derivatives along the double-integrator flow equal
(eta2, alpha1 + beta1 a, xi2, alpha2 + beta2 a, phi2, alpha3 + beta3 a) everywhere in the tube,
checked by central differences (Richardson-extrapolated) at random states, on Frenet and
rotation-minimising frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pf_offboard.control import evaluate_terms
from pf_offboard.control.transverse import inverse_columns
from pf_offboard.path import Path

N_STATES = 60  # per (path, frame): 240 states in all


def closest_lam(path: Path, y: np.ndarray, lam0: float) -> float:
    """Newton on <sigma'(lam), y - sigma(lam)> = 0 to machine precision (the branch through lam0)."""
    lam = lam0
    for _ in range(60):
        s = np.array(path.eval_floats(lam)).reshape(5, 3)
        r = y - s[0]
        g = s[1] @ r
        dg = s[2] @ r - s[1] @ s[1]
        step = g / dg
        lam -= step
        if abs(step) < 1e-15 * max(1.0, abs(lam)):
            break
    return lam


def random_state(path: Path, rng: np.random.Generator):
    """(y, v, a, lam*) with y inside the tube (q = <sigma'', r>/|sigma'|^2 <= 0.7), |r| <= 1.5 m."""
    while True:
        lam = rng.uniform(0.05, 0.95) * path.lam_max
        fr = path.frame(lam)
        pt = path.eval(lam)
        rho = rng.uniform(0.0, 1.5)
        th = rng.uniform(0.0, 2.0 * np.pi)
        r = rho * (math.cos(th) * fr.e2 + math.sin(th) * fr.e3)
        q = pt.d2 @ r / (pt.d1 @ pt.d1)
        if q <= 0.7:
            break
    y = pt.sigma + r
    v = rng.uniform(-3.0, 3.0, 3)
    a = rng.uniform(-10.0, 10.0, 3)
    return y, v, a, lam


def observed(path: Path, y: np.ndarray, v: np.ndarray, lam0: float) -> tuple[np.ndarray, float]:
    lam = closest_lam(path, y, lam0)
    t = evaluate_terms(path, lam, y, v)
    return np.array(t.state), lam


def fd_derivative(path: Path, y, v, a, lam0: float, h: float) -> np.ndarray:
    def at(dt: float) -> np.ndarray:
        return observed(path, y + v * dt + 0.5 * a * dt * dt, v + a * dt, lam0)[0]

    d1 = (at(h) - at(-h)) / (2 * h)
    d2 = (at(h / 2) - at(-h / 2)) / h
    return (4.0 * d2 - d1) / 3.0


@pytest.mark.parametrize("name", ["paper_path", "paper_path_rmf", "helix_frenet", "helix_rmf"])
def test_exact_coordinates_match_finite_differences(name, request):
    path: Path = request.getfixturevalue(name)
    rng = np.random.default_rng(20240 + len(name))
    worst = 0.0
    for _ in range(N_STATES):
        y, v, a, lam0 = random_state(path, rng)
        lam = closest_lam(path, y, lam0)
        terms = evaluate_terms(path, lam, y, v)
        st = np.array(terms.state)
        beta = np.array((terms.beta1, terms.beta2, terms.beta3))
        predicted = np.empty(6)
        predicted[0::2] = st[1::2]  # d/dt (eta1, xi1, phi1) = (eta2, xi2, phi2)
        predicted[1::2] = np.array(terms.alpha) + beta @ a
        fd = fd_derivative(path, y, v, a, lam, 2e-4)
        err = np.abs(fd - predicted) / np.maximum(1.0, np.abs(predicted))
        worst = max(worst, float(err.max()))
        assert err.max() <= 1e-6, (name, y, v, a, fd, predicted)
    print(f"{name}: worst relative error {worst:.2e}")
    assert worst > 0.0  # the comparison really ran


def test_on_path_values_reduce_to_the_paper(paper_path):
    """On the path (r = 0) the exact T(x), beta equal the paper's (10)-(16); on the path
    following manifold (r = 0, v tangent) alpha equals the paper's too. (With r = 0 but a normal
    velocity the paper's alpha1 is the derivative of <t, v>, not of eta1's true rate.)"""
    rng = np.random.default_rng(7)
    for _ in range(20):
        lam = rng.uniform(0.0, paper_path.lam_max)
        pt = paper_path.eval(lam)
        fr = paper_path.frame(lam)
        v = rng.uniform(-2, 2, 3)
        t = evaluate_terms(paper_path, lam, pt.sigma, v)
        assert t.state.eta2 == pytest.approx(fr.t @ v, abs=1e-12)
        assert t.state.xi2 == pytest.approx(fr.e2 @ v, abs=1e-12)
        assert t.state.phi2 == pytest.approx(fr.e3 @ v, abs=1e-12)
        assert np.allclose(t.beta1, fr.t, atol=1e-12)
        assert np.allclose(t.beta2, fr.e2, atol=1e-12)
        assert np.allclose(t.beta3, fr.e3, atol=1e-12)
        eta2 = rng.uniform(-2, 2)
        s = np.linalg.norm(pt.d1)
        t = evaluate_terms(paper_path, lam, pt.sigma, eta2 * fr.t)
        ld = eta2 / s
        assert t.alpha[0] == pytest.approx(ld * (fr.dt @ (eta2 * fr.t)), abs=1e-9)  # = 0
        # paper (16): alpha2 = ld <e2', 2 v - eta2 t> (the r terms vanish)
        assert t.alpha[1] == pytest.approx(ld * (fr.de2 @ (eta2 * fr.t)), abs=1e-9)
        assert t.alpha[2] == pytest.approx(ld * (fr.de3 @ (eta2 * fr.t)), abs=1e-9)


def test_tube_measure_is_kappa_xi1_for_frenet(helix_frenet):
    path = helix_frenet
    lam = 0.3 * path.lam_max
    pt, fr = path.eval(lam), path.frame(lam)
    y = pt.sigma + 0.4 * fr.e2 + 0.3 * fr.e3
    t = evaluate_terms(path, lam, y, np.zeros(3))
    assert t.tube == pytest.approx(path.curvature(lam) * t.state.xi1, rel=1e-9)


def test_inverse_columns_closed_form():
    rng = np.random.default_rng(3)
    for _ in range(50):
        b = rng.normal(size=(3, 3))
        cols = inverse_columns(*map(tuple, b))
        assert cols is not None
        assert np.allclose(b @ np.array(cols).T, np.eye(3), atol=1e-9)
    assert inverse_columns((1.0, 0.0, 0.0), (2.0, 0.0, 0.0), (0.0, 0.0, 1.0)) is None


def test_paper_on_path_rate_is_not_exact_off_the_path(paper_path):
    """The check above can fail: with the paper's dlam/dt = <t, v>/|sigma'| (exact only on the
    path) xi2 of eq. (12) misses the finite-difference rate of xi1 off the path."""
    rng = np.random.default_rng(99)
    misses = 0
    for _ in range(20):
        y, v, a, lam0 = random_state(paper_path, rng)
        lam = closest_lam(paper_path, y, lam0)
        pt, fr = paper_path.eval(lam), paper_path.frame(lam)
        r = y - pt.sigma
        if np.linalg.norm(r) < 0.3:
            continue
        xi2_paper = (fr.t @ v) / np.linalg.norm(pt.d1) * (fr.de2 @ r) + fr.e2 @ v
        fd = fd_derivative(paper_path, y, v, a, lam, 2e-4)[2]
        exact = evaluate_terms(paper_path, lam, y, v).state.xi2
        assert abs(fd - exact) <= 1e-6 * max(1.0, abs(exact))
        misses += abs(fd - xi2_paper) > 1e-3
    assert misses >= 5
