"""Closest-point projection: global init, warm start, self-intersection, wrap, clamp, jumps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from pf_offboard.errors import InputError
from pf_offboard.path import Path, Projector


def brute_force(path: Path, y: np.ndarray, n: int = 40000) -> tuple[float, float]:
    """Independent reference: dense sampling, then bounded scalar minimisation around the best."""
    lam = np.linspace(0.0, path.lam_max, n)
    pts = path._spline.eval_vectorised(lam, 0)
    d = np.linalg.norm(pts - y, axis=1)
    best = (np.inf, 0.0)
    # Refine the few best sampled local minima (ties at a self-intersection).
    for k in np.argsort(d)[:20]:
        lo, hi = lam[max(k - 1, 0)], lam[min(k + 1, n - 1)]
        r = minimize_scalar(
            lambda x: float(np.linalg.norm(path.eval(x).sigma - y)),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-11},
        )
        if r.fun < best[0]:
            best = (float(r.fun), float(r.x))
    return best[1], best[0]


def dist(path: Path, lam: float, y: np.ndarray) -> float:
    return float(np.linalg.norm(path.eval(lam).sigma - y))


def near_points(path: Path, rng: np.random.Generator, n: int, radius: float) -> list[np.ndarray]:
    out = []
    for lam in rng.uniform(0, path.lam_max, n):
        v = rng.normal(size=3)
        out.append(path.eval(lam).sigma + radius * rng.uniform() * v / np.linalg.norm(v))
    return out


@pytest.mark.parametrize("name", ["paper", "figure8", "helix"])
def test_fresh_projection_equals_brute_force(name, request):
    path = request.getfixturevalue(name)
    proj = Projector(path)
    for y in near_points(path, np.random.default_rng(6), 25, 0.6):
        proj.reset()
        lam = proj.update(y)
        lam_ref, d_ref = brute_force(path, y)
        assert 0.0 <= lam <= path.lam_max
        assert dist(path, lam, y) <= d_ref + 1e-9
        assert proj.distance_m == pytest.approx(dist(path, lam, y), abs=1e-12)
        # The minimiser itself (unique for these points unless two branches tie).
        if abs(dist(path, lam_ref, y) - dist(path, lam, y)) < 1e-9 and abs(lam - lam_ref) > 1e-4:
            continue  # an exact tie between branches; either is a closest point
        gap = abs(lam - lam_ref)
        if path.closed:
            gap = min(gap, path.lam_max - gap)
        assert gap < 1e-6


@pytest.mark.parametrize("name", ["paper", "helix"])
def test_warm_started_tracking_equals_brute_force(name, request):
    path = request.getfixturevalue(name)
    rng = np.random.default_rng(7)
    proj = Projector(path, check_every=0)  # pure warm start after the first call
    offset = np.array([0.15, -0.1, 0.2])
    lams = np.linspace(0.2, path.lam_max - 0.2, 600)
    for i, lam0 in enumerate(lams):
        y = path.eval(lam0).sigma + offset + 0.01 * rng.normal(size=3)
        lam = proj.update(y)
        if i % 37 == 0 and not _near_crossing(path, lam0):
            _, d_ref = brute_force(path, y)
            assert dist(path, lam, y) <= d_ref + 1e-9
        # Newton converges fully every step: the closest-point condition holds.
        p = path.eval(lam)
        if 0.0 < lam < path.lam_max:
            assert abs(np.dot(p.d1, p.sigma - y)) < 1e-9
    assert proj.n_global == 1


def _near_crossing(path: Path, lam: float) -> bool:
    """Within 1 m (parameter) of a visit of a repeated way-point: the other branch may be closer
    than the tracked one there, and the tracker deliberately keeps its branch."""
    w = path.waypoints
    if len(np.unique(w, axis=0)) == len(w):
        return False
    return any(min(abs(lam - c), path.lam_max - abs(lam - c)) < 1.0 for c in _crossing(path))


def _crossing(path: Path) -> tuple[float, float]:
    """Parameters of the two visits of the repeated way-point."""
    w = path.waypoints
    knots = path._spline.knots
    for i in range(len(w)):
        for j in range(i + 1, len(w)):
            if np.allclose(w[i], w[j]):
                return float(knots[i]), float(knots[j])
    raise AssertionError("no repeated way-point")


@pytest.mark.parametrize("name", ["paper", "figure8", "paper_rmf"])
@pytest.mark.parametrize("direction", [1.0, -1.0])
@pytest.mark.parametrize("offset", [0.0, 0.05, 0.3])
@pytest.mark.parametrize("side", ["e2", "e3"])
def test_self_intersection_keeps_lambda_monotonic(name, direction, offset, side, request):
    path = request.getfixturevalue(name)
    for lam_c in _crossing(path):
        proj = Projector(path)
        step = 0.015  # 1.5 m/s at 100 Hz
        lams = lam_c + direction * np.arange(-1.0, 1.0, step)
        prev = None
        for lam0 in lams:
            f = path.frame(path.wrap(lam0))
            y = path.eval(path.wrap(lam0)).sigma + offset * getattr(f, side)
            lam = proj.update(y)
            if prev is not None:
                d = (lam - prev + path.lam_max / 2) % path.lam_max - path.lam_max / 2
                assert 0 < direction * d < 3 * step, (lam0, prev, lam)
            prev = lam
        # It stayed on its own branch: it ends up 1 m beyond the crossing along it.
        end = path.wrap(lams[-1])
        gap = abs(prev - end)
        assert min(gap, path.lam_max - gap) < 0.05


def test_branch_is_not_switched_even_by_the_periodic_check(paper):
    # Sitting exactly at the crossing point for many calls: both branches are at distance 0.
    lam_a, lam_b = _crossing(paper)
    c = paper.eval(lam_a).sigma
    for lam_start in (lam_a, lam_b):
        proj = Projector(paper, check_every=1)
        proj.update(paper.eval(lam_start - 0.05).sigma)
        for _ in range(60):
            lam = proj.update(c + 1e-3 * np.array([0.3, -0.2, 0.1]))
        assert abs(lam - lam_start) < 0.01
        assert proj.n_global == 1


def test_wraps_on_closed_paths(paper):
    proj = Projector(paper)
    lams = np.arange(paper.lam_max - 1.0, paper.lam_max + 1.0, 0.02)
    out = []
    for lam0 in lams:
        out.append(proj.update(paper.eval(lam0).sigma + np.array([0.0, 0.0, 0.1])))
    out = np.array(out)
    assert np.all((out >= 0.0) & (out < paper.lam_max))
    assert out[0] > paper.lam_max - 1.1 and out[-1] < 1.1
    unwrapped = np.unwrap(out, period=paper.lam_max)
    assert np.all(np.diff(unwrapped) > 0)
    assert proj.n_global == 1


def test_clamps_at_open_ends(helix):
    proj = Projector(helix)
    end = helix.eval(helix.lam_max)
    t_end = end.d1 / np.linalg.norm(end.d1)
    # Walk along the path and on past its end along the tangent: lambda* stops at lam_max.
    for lam0 in np.arange(helix.lam_max - 0.5, helix.lam_max, 0.02):
        proj.update(helix.eval(lam0).sigma)
    for s in np.arange(0.0, 0.8, 0.02):
        lam = proj.update(end.sigma + s * t_end)
    assert lam == helix.lam_max
    start = helix.eval(0.0)
    proj.reset()
    assert proj.update(start.sigma - 0.5 * start.d1 / np.linalg.norm(start.d1)) == 0.0


def test_a_jump_reinitialises(paper):
    proj = Projector(paper)
    proj.update(paper.eval(1.0).sigma)
    assert proj.n_global == 1
    proj.update(paper.eval(1.01).sigma)
    assert proj.n_global == 1
    y = paper.eval(9.0).sigma + np.array([0.0, 0.1, 0.0])  # metres away from the last position
    lam = proj.update(y)
    assert proj.n_global == 2
    _, d_ref = brute_force(paper, y)
    assert dist(paper, lam, y) <= d_ref + 1e-9
    assert lam == pytest.approx(9.0, abs=0.2)


def test_reset_forgets_the_warm_start(paper):
    proj = Projector(paper)
    proj.update(paper.eval(2.0).sigma)
    assert proj.lam == pytest.approx(2.0, abs=1e-9)
    proj.reset()
    assert proj.lam is None
    proj.update(paper.eval(2.0).sigma)
    assert proj.n_global == 2


def _hairpin() -> Path:
    pts = [(0, 0, 2), (2, 0, 2), (4, 0, 2), (5.5, 1.5, 2), (4, 3, 2), (2, 3, 2), (0, 3, 2)]
    return Path.from_waypoints(np.array(pts, dtype=float))


def _walk_across(proj: Projector) -> float:
    # From arm A (y = 0) sideways in 2 cm steps to arm B (y = 3): the local minimum on arm A
    # persists all the way, so only a global look can switch to arm B.
    for y in np.arange(0.0, 3.0, 0.02):
        lam = proj.update(np.array([1.0, y, 2.0]))
    return lam


def test_periodic_global_check_recovers_a_lost_track():
    path = _hairpin()
    proj = Projector(path, check_every=10)
    lam = _walk_across(proj)
    assert proj.n_global >= 2
    lam_ref, _ = brute_force(path, np.array([1.0, 2.98, 2.0]))
    assert lam == pytest.approx(lam_ref, abs=1e-6)
    assert lam > path.lam_max / 2  # on arm B
    # Without the check the warm start stays on arm A (what the check is for).
    proj = Projector(path, check_every=0)
    lam = _walk_across(proj)
    assert proj.n_global == 1
    assert lam < path.lam_max / 2  # still on arm A


def test_rejects_non_finite_positions(paper):
    proj = Projector(paper)
    with pytest.raises(InputError) as exc:
        proj.update(np.array([0.0, np.nan, 1.0]))
    assert exc.value.field == "position_enu_m"
    assert proj.lam is None  # nothing was stored


def test_accepts_lists_and_tuples(paper):
    proj = Projector(paper)
    y = paper.eval(3.0).sigma
    assert proj.update(list(y)) == pytest.approx(3.0, abs=1e-9)
    assert proj.update(tuple(y)) == pytest.approx(3.0, abs=1e-9)


@pytest.mark.parametrize(
    "kw, field",
    [({"window_m": 0.0}, "projector.window_m"), ({"jump_m": np.nan}, "projector.jump_m"),
     ({"check_every": -1}, "projector.check_every"), ({"reinit_margin_m": -1.0}, "projector.reinit_margin_m")],
)
def test_bad_projector_settings(paper, kw, field):
    with pytest.raises(InputError) as exc:
        Projector(paper, **kw)
    assert exc.value.field == field


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_random_paths_fresh_projection_is_global(seed):
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.uniform(-1.0, 1.0, size=(8, 3)) + np.array([1.0, 0.3, 0.0]), axis=0)
    path = Path.from_waypoints(pts, closed=False, frame="rmf")
    proj = Projector(path)
    for y in near_points(path, rng, 10, 1.5):
        proj.reset()
        lam = proj.update(y)
        _, d_ref = brute_force(path, y)
        assert dist(path, lam, y) <= d_ref + 1e-9


def _tight_helix() -> Path:
    """Turns 0.4 m apart (radius 1.25 m): a point 0.2 m off one turn is as near the next."""
    import math

    pts = [[1.25 * math.cos(i * math.pi / 5), 1.25 * math.sin(i * math.pi / 5), 1.6 + 0.04 * i] for i in range(41)]
    return Path(np.array(pts), closed=False, frame="auto")


def test_seed_keeps_a_nearby_point_on_the_seeding_branch() -> None:
    path = _tight_helix()
    below = np.array([1.0, 0.0, 2.17])  # 0.17 m above the turn at z 2.0, 0.23 m below the one at 2.4
    above = below + np.array([0.0, 0.0, 0.1])  # nearer the upper turn
    lam_below = Projector(path).update(below)
    lam_alone = Projector(path).update(above)
    assert abs(path.eval_floats(lam_below)[2] - 2.0) < 0.05 and abs(path.eval_floats(lam_alone)[2] - 2.4) < 0.05
    seeded = Projector(path)
    seeded.seed(lam_below, above, below)
    lam = seeded.update(above)
    assert abs(lam - lam_below) < 0.3  # the lower turn, not the nearer upper one
    # and a point ahead along the path is found ahead on that branch (the seed moves along the tangent)
    ahead = np.asarray(path.eval_floats(lam_below + 0.7)[0:3]) + np.array([0.0, 0.0, 0.17])
    seeded.seed(lam_below, ahead, below)
    assert abs(seeded.update(ahead) - (lam_below + 0.7)) < 0.05


def test_seed_refuses_non_finite() -> None:
    with pytest.raises(InputError, match="position_enu_m"):
        Projector(_tight_helix()).seed(float("nan"), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
