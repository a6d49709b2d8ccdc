"""The reference path: quintic spline through way-points, arclength, moving frame.

World frame ENU, metres. The parameter lambda is the cumulative chord length of the way-points
(metres, ``|sigma'| ~ 1``), lambda in [0, lam_max]; closed paths are periodic in lambda.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.errors import InputError
from pf_offboard.path._vec import Jet
from pf_offboard.path.moving_frame import RotationMinimisingFrame, frenet_jets
from pf_offboard.path.spline import QuinticSpline, interval

# Frame choice for frame="auto": Frenet-Serret when the curvature sampled every <= 5 cm of
# parameter stays at or above both an absolute floor and a fraction of its mean, else the
# rotation-minimising frame (FS normal p and its derivatives blow up where kappa -> 0).
AUTO_FRENET_MIN_KAPPA_1_M = 0.1
AUTO_FRENET_MIN_KAPPA_REL = 0.2
# Forcing frame="frenet" is refused below this curvature (radius 100 m): the FS frame is
# undefined (or numerically meaningless) there.
FRENET_MIN_KAPPA_1_M = 1e-2
# Parameter spacing of the sample grid (RMF nodes, curvature check, arclength table), metres.
GRID_STEP_M = 0.05
# Way-points closer than this are duplicates.
DUPLICATE_TOL_M = 1e-6
# Way-points farther from the origin are refused: the sampled path grows with its length (a 5 km
# loop takes ~5 s to build) and the spline fit loses conditioning beyond that; a flight path in a
# local frame is much smaller (a value this large usually means wrong units).
MAX_WAYPOINT_ABS_M = 5000.0

_FRAMES = ("auto", "frenet", "rmf")

# Chebyshev points of the first kind on [-1, 1] and the integration matrix for the arclength
# table: |sigma'| is interpolated at these 9 points per grid interval and integrated exactly.
_CHEB_N = 9
_CHEB_X = np.cos(np.pi * (2 * np.arange(_CHEB_N) + 1) / (2 * _CHEB_N))
_CHEB_VINV = np.linalg.inv(np.vander(_CHEB_X, _CHEB_N, increasing=True))


class PathPoint(NamedTuple):
    """sigma(lambda) (m, ENU) and its derivatives with respect to lambda, each ndarray (3,)."""

    sigma: NDArray[np.float64]
    d1: NDArray[np.float64]
    d2: NDArray[np.float64]
    d3: NDArray[np.float64]
    d4: NDArray[np.float64]


class FrameDerivs(NamedTuple):
    """Moving frame (t, e2, e3) at lambda with d/dlambda (d*) and d^2/dlambda^2 (dd*), ndarray (3,).

    Frenet-Serret: e2 = p (normal), e3 = b (binormal). Right-handed: e3 = t x e2.
    """

    t: NDArray[np.float64]
    e2: NDArray[np.float64]
    e3: NDArray[np.float64]
    dt: NDArray[np.float64]
    de2: NDArray[np.float64]
    de3: NDArray[np.float64]
    ddt: NDArray[np.float64]
    dde2: NDArray[np.float64]
    dde3: NDArray[np.float64]


def _check_finite(value: float, name: str) -> None:
    if not math.isfinite(value):
        raise InputError(name, f"not finite: {value}")


def _validate(points: ArrayLike, closed: bool) -> NDArray[np.float64]:
    if not isinstance(closed, (bool, np.bool_)):
        raise InputError("closed", f"must be true or false, got {closed!r}")
    try:
        pts = np.array(points, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:  # OverflowError: an integer beyond float range
        raise InputError("waypoints", f"not an (N, 3) array of numbers ({' '.join(str(exc).split())[:120]})") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError("waypoints", f"expected shape (N, 3) in metres, got {pts.shape}")
    for i, p in enumerate(pts):
        if not np.all(np.isfinite(p)):
            raise InputError(f"waypoints[{i}]", f"not finite: {p.tolist()}")
        if np.abs(p).max() > MAX_WAYPOINT_ABS_M:
            raise InputError(
                f"waypoints[{i}]", f"coordinate beyond {MAX_WAYPOINT_ABS_M:g} m of the origin (units?): {p.tolist()}"
            )
    need = 3 if closed else 2
    kind = "closed" if closed else "open"
    if len(pts) < need:
        raise InputError("waypoints", f"a {kind} path needs at least {need} distinct way-points, got {len(pts)}")
    for i in range(1, len(pts)):
        if np.linalg.norm(pts[i] - pts[i - 1]) <= DUPLICATE_TOL_M:
            raise InputError(f"waypoints[{i}]", f"duplicate of waypoints[{i - 1}] (consecutive way-points must differ)")
    if closed and np.linalg.norm(pts[-1] - pts[0]) <= DUPLICATE_TOL_M:
        raise InputError(
            f"waypoints[{len(pts) - 1}]",
            "equals waypoints[0]; a closed path closes itself: do not repeat the first point at the end",
        )
    distinct = len(np.unique(np.round(pts / DUPLICATE_TOL_M), axis=0))
    if distinct < need:
        raise InputError("waypoints", f"a {kind} path needs at least {need} distinct way-points, got {distinct}")
    return pts


class Path:
    """Reference path sigma: [0, lam_max] -> R^3 (ENU, m). Build with :meth:`from_waypoints`."""

    def __init__(self, waypoints: NDArray[np.float64], closed: bool, frame: str) -> None:
        waypoints = np.array(waypoints, dtype=float)
        waypoints.flags.writeable = False  # the spline was built from them
        self.waypoints = waypoints
        self.closed = bool(closed)
        self._spline = sp = QuinticSpline(waypoints, self.closed)
        self.lam_max = sp.lam_max
        # Sample grid: every spline segment split into equal steps of at most GRID_STEP_M.
        nodes = [0.0]
        for a, b in zip(sp.knots[:-1], sp.knots[1:]):
            m = max(2, math.ceil((b - a) / GRID_STEP_M))
            nodes.extend(np.linspace(a, b, m + 1)[1:].tolist())
        grid = np.array(nodes)
        grid[-1] = self.lam_max
        self._grid = grid
        d1 = sp.eval_vectorised(grid, 1)
        d2 = sp.eval_vectorised(grid, 2)
        speed = np.linalg.norm(d1, axis=1)
        if speed.min() < 0.05:
            i = int(np.argmin(speed))
            raise InputError(
                "waypoints",
                f"the spline almost stops (|dsigma/dlambda| = {speed.min():.3g}) near lambda = {grid[i]:.3f} m; "
                "way-points double back too sharply",
            )
        kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / speed**3
        self.kappa_min = float(kappa.min())
        self.kappa_max = float(kappa.max())
        self._build_arclength(grid)
        if frame not in _FRAMES:
            raise InputError("path.moving_frame", f"must be one of {', '.join(_FRAMES)}, got {frame!r}")
        if frame == "auto":
            ok = self.kappa_min >= AUTO_FRENET_MIN_KAPPA_1_M and self.kappa_min >= AUTO_FRENET_MIN_KAPPA_REL * float(
                kappa.mean()
            )
            frame = "frenet" if ok else "rmf"
        elif frame == "frenet" and self.kappa_min < FRENET_MIN_KAPPA_1_M:
            i = int(np.argmin(kappa))
            raise InputError(
                "path.moving_frame",
                f"frenet needs nonzero curvature, but kappa = {self.kappa_min:.2g} 1/m at lambda = {grid[i]:.3f} m "
                "(straight piece or inflection); use rmf or auto",
            )
        self.frame_kind = frame
        self._rmf = RotationMinimisingFrame(sp, grid) if frame == "rmf" else None
        self._frame_cache: tuple[float, FrameDerivs] | None = None
        # Single-entry caches of the fast float forms (NaN never equals itself: empty cache).
        self._ev_lam = math.nan
        self._ev_val: tuple[float, ...] = ()
        self._fj_lam = math.nan
        self._fj_val: tuple[Jet, Jet, Jet] | None = None

    @classmethod
    def from_waypoints(cls, points: ArrayLike, closed: bool = False, frame: str = "auto") -> Path:
        """Quintic (C4) spline through ``points`` ((N, 3), metres, ENU z up).

        ``closed``: periodic (do not repeat the first point at the end). ``frame``: moving frame,
        ``"auto"`` | ``"frenet"`` | ``"rmf"``. Raises :class:`InputError` naming the bad way-point.
        """
        return cls(_validate(points, closed), bool(closed), frame)

    # ------------------------------------------------------------------ parameter handling
    def wrap(self, lam: float) -> float:
        """Into [0, lam_max) for closed paths (periodic), clamped to [0, lam_max] for open ones."""
        lam = float(lam)
        if not 0.0 <= lam <= self.lam_max:  # (NaN fails this test too) the check costs nothing in range
            _check_finite(lam, "lam")
        if self.closed:
            r = lam % self.lam_max
            return 0.0 if r >= self.lam_max else r
        return 0.0 if lam < 0.0 else (self.lam_max if lam > self.lam_max else lam)

    def _inrange(self, lam: float) -> float:
        # Closed: periodic. Open: no clamping, the end polynomials extend the curve smoothly.
        if not 0.0 <= lam < self.lam_max:
            _check_finite(lam, "lam")
            if self.closed:
                r = lam % self.lam_max
                return 0.0 if r >= self.lam_max else r
        return lam

    # ------------------------------------------------------------------ geometry
    def eval_floats(self, lam: float) -> tuple[float, ...]:
        """sigma..sigma'''' at ``lam`` as 15 floats (x, y, z per order); fast internal form.

        The last result is cached (a control step asks for the same lambda several times).
        """
        if lam == self._ev_lam:
            return self._ev_val
        val = self._spline.eval_floats(self._inrange(float(lam)))
        self._ev_lam, self._ev_val = lam, val
        return val

    def eval(self, lam: float) -> PathPoint:
        """sigma(lam) (m, ENU) and d^k sigma / d lam^k, k = 1..4."""
        a = np.array(self._spline.eval_floats(self._inrange(float(lam)))).reshape(5, 3)
        return PathPoint(a[0], a[1], a[2], a[3], a[4])

    def curvature(self, lam: float) -> float:
        """kappa(lam) = |sigma' x sigma''| / |sigma'|^3, 1/m (tube condition: |kappa xi1| < 1)."""
        s = self._spline.eval2_floats(self._inrange(float(lam)))
        ax, ay, az, bx, by, bz = s[3:9]
        cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        return math.sqrt(cx * cx + cy * cy + cz * cz) / (ax * ax + ay * ay + az * az) ** 1.5

    def frame_jets(self, lam: float) -> tuple[Jet, Jet, Jet]:
        """``(t, e2, e3)`` jets, each (value, d/dlam, d2/dlam2) as float 3-tuples; fast internal form.

        The last result is cached (immutable tuples).
        """
        if lam == self._fj_lam:
            return self._fj_val
        s = self.eval_floats(lam)
        val = frenet_jets(s) if self._rmf is None else self._rmf.jets(s, self._inrange(float(lam)))
        self._fj_lam, self._fj_val = lam, val
        return val

    def frame(self, lam: float) -> FrameDerivs:
        """Moving frame at ``lam`` with exact first and second lambda-derivatives."""
        lam = float(lam)
        cache = self._frame_cache
        if cache is not None and cache[0] == lam:
            return cache[1]
        (t, t1, t2), (e, e1, e2), (b, b1, b2) = self.frame_jets(lam)
        a = np.array((t, e, b, t1, e1, b1, t2, e2, b2))
        a.flags.writeable = False  # the result is cached: nobody may modify it in place
        out = FrameDerivs(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8])
        self._frame_cache = (lam, out)
        return out

    # ------------------------------------------------------------------ arclength
    def _build_arclength(self, grid: NDArray[np.float64]) -> None:
        # Per grid interval, |sigma'| is interpolated by a degree-8 polynomial at Chebyshev points
        # and integrated exactly: error far below 1e-12 m on 5 cm intervals of a smooth speed.
        h = np.diff(grid)
        xs = grid[:-1, None] + 0.5 * h[:, None] * (_CHEB_X[None, :] + 1.0)
        speed = np.linalg.norm(self._spline.eval_vectorised(xs.ravel(), 1), axis=1).reshape(xs.shape)
        a = speed @ _CHEB_VINV.T  # monomial coefficients in x in [-1, 1]
        k = np.arange(_CHEB_N)
        # s(x) - s(-1) = h/2 * sum a_k (x^(k+1) - (-1)^(k+1)) / (k+1)
        ic = np.zeros((len(h), _CHEB_N + 1))
        ic[:, 1:] = 0.5 * h[:, None] * a / (k + 1)
        ic[:, 0] = -np.sum(ic[:, 1:] * (-1.0) ** (k + 1), axis=1)
        # Integral over a full interval is the value at x = 1 (ic[:, 0] already removes x = -1).
        full = ic.sum(axis=1)
        cum = np.concatenate([[0.0], np.cumsum(full)])
        self.length_m = float(cum[-1])
        self._cum = cum.tolist()
        self._grid_list = grid.tolist()
        self._ngrid = len(h)
        self._arc_coef = [tuple(row[::-1].tolist()) for row in ic]  # highest power first (Horner)
        self._half_h = (0.5 * h).tolist()

    def _arc_in(self, i: int, lam: float) -> float:
        # Arclength from grid interval i's polynomial (also valid slightly outside the interval).
        x = (lam - self._grid_list[i]) / self._half_h[i] - 1.0
        v = 0.0
        for c in self._arc_coef[i]:
            v = v * x + c
        return self._cum[i] + v

    def arclength(self, lam: float) -> float:
        """eta1(lam) = integral_0^lam |sigma'| (m), of the wrapped (closed) / clamped (open) lam."""
        lam = self.wrap(lam)
        return self._arc_in(interval(self._grid_list, self._ngrid, lam), lam)

    def lam_at_arclength(self, s_m: float) -> float:
        """Inverse of :meth:`arclength` (Newton to 1e-13). Closed: s wraps; open: clamped."""
        s = float(s_m)
        _check_finite(s, "s_m")
        if self.closed:
            s %= self.length_m
        else:
            s = min(max(s, 0.0), self.length_m)
        i = interval(self._cum, self._ngrid, s)
        c0, c1 = self._cum[i], self._cum[i + 1]
        g0, g1 = self._grid_list[i], self._grid_list[i + 1]
        lam = g0 + (g1 - g0) * (s - c0) / (c1 - c0)
        for _ in range(8):
            d = self._spline.eval2_floats(lam)
            step = (self._arc_in(i, lam) - s) / math.sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5])
            lam -= step
            if abs(step) < 1e-13 * (1.0 + abs(lam)):
                break
        return self.wrap(lam)

    def __repr__(self) -> str:
        kind = "closed" if self.closed else "open"
        return (
            f"Path({kind}, {len(self.waypoints)} way-points, length {self.length_m:.3f} m, "
            f"frame {self.frame_kind})"
        )
