"""Quintic-spline interpolation of way-points, stored as per-segment Taylor polynomials.

The spline is built once with :func:`scipy.interpolate.make_interp_spline` (degree 5) and then
converted to one polynomial per knot interval, expanded about the interval's midpoint. Evaluation is
Horner's rule on plain Python floats: on the control hot path a handful of float operations is far
cheaper than any sequence of tiny numpy calls.

Parametrisation: cumulative chord length (metres), so ``|sigma'(lam)|`` is close to 1.
End conditions of open paths: "natural" quintic spline, ``sigma''' = sigma'''' = 0`` at both ends
(the interpolant minimising the integral of ``|sigma'''|^2``); a two-point open path is the straight
segment between its points. Closed paths are periodic: C4 across the seam.
"""

from __future__ import annotations

from bisect import bisect_right
from math import perm

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import make_interp_spline


class QuinticSpline:
    """C4 piecewise quintic curve R -> R^3 through the way-points at chord-length knots.

    ``knots`` (m+1,) are the parameter values of the way-points (m segments). For closed curves the
    parameter is periodic with period ``lam_max`` and ``knots[-1] == lam_max``.
    """

    __slots__ = ("knots", "lam_max", "closed", "_centres", "_knot_list", "_nseg", "coef_array", "centres", "_flat")

    def __init__(self, points: NDArray[np.float64], closed: bool) -> None:
        pts = np.asarray(points, dtype=float)
        if closed:
            pts = np.vstack([pts, pts[:1]])
        chords = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        knots = np.concatenate([[0.0], np.cumsum(chords)])
        self.knots = knots
        self.lam_max = float(knots[-1])
        self.closed = closed
        nseg = len(knots) - 1
        centres = 0.5 * (knots[:-1] + knots[1:])
        # taylor[i, k, :] = sigma^(k)(centre_i) / k!
        taylor = np.zeros((nseg, 6, 3))
        if len(pts) == 2 and not closed:
            # Straight segment: sigma = p0 + (lam / h) (p1 - p0), |sigma'| = 1 exactly.
            d = (pts[1] - pts[0]) / chords[0]
            taylor[0, 0] = 0.5 * (pts[0] + pts[1])
            taylor[0, 1] = d
        else:
            if closed:
                bc = "periodic"
            else:
                z = np.zeros(3)
                bc = ([(3, z), (4, z)], [(3, z), (4, z)])
            bspl = make_interp_spline(knots, pts, k=5, bc_type=bc)
            fact = 1.0
            for k in range(6):
                if k > 0:
                    fact *= k
                # At an interval's midpoint the B-spline evaluates that interval's polynomial,
                # so no one-sided knot ambiguity arises; degree 5 makes the Taylor series exact.
                taylor[:, k, :] = bspl(centres, nu=k) / fact
        self.centres = centres
        self.coef_array = taylor
        # One flat 20-tuple per segment and axis (see flat_layout): orders 0..4 back to back.
        self._flat = list(zip(*(flat_layout(taylor[:, :, ax], 5) for ax in range(3))))
        self._centres = [float(c) for c in centres]
        self._knot_list = [float(k) for k in knots]
        self._nseg = nseg

    def eval_floats(self, lam: float) -> tuple[float, ...]:
        """sigma and derivatives 1..4 at ``lam`` (not wrapped): 15 floats, (x, y, z) per order."""
        i = interval(self._knot_list, self._nseg, lam)
        u = lam - self._centres[i]
        cx, cy, cz = self._flat[i]
        x = _horner4(cx, u)
        y = _horner4(cy, u)
        z = _horner4(cz, u)
        return (x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2], x[3], y[3], z[3], x[4], y[4], z[4])

    def eval2_floats(self, lam: float) -> tuple[float, ...]:
        """sigma, sigma', sigma'' at ``lam`` (not wrapped): 9 floats (projection hot path)."""
        i = interval(self._knot_list, self._nseg, lam)
        return horner2_xyz(self._flat[i], lam - self._centres[i])

    def eval_vectorised(self, lam: NDArray[np.float64], nu: int = 0) -> NDArray[np.float64]:
        """sigma^(nu) at many (already wrapped / in-range) parameters, shape (n, 3). Build-time use."""
        lam = np.asarray(lam, dtype=float)
        idx = np.clip(np.searchsorted(self.knots, lam, side="right") - 1, 0, self._nseg - 1)
        u = (lam - self.centres[idx])[:, None]
        a = self.coef_array[idx]  # (n, 6, 3)
        out = np.zeros((len(lam), 3))
        for j in range(5, nu - 1, -1):
            f = 1.0
            for m in range(j - nu + 1, j + 1):
                f *= m
            out = out * u + a[:, j, :] * f
        return out


def _horner4(c: tuple[float, ...], u: float) -> tuple[float, float, float, float, float]:
    """Values at ``u`` of the five pre-multiplied polynomials (orders 0..4) in a flat 20-tuple."""
    p0, p1, p2, p3, p4, p5, q0, q1, q2, q3, q4, r0, r1, r2, r3, s0, s1, s2, t0, t1 = c
    return (
        p0 + u * (p1 + u * (p2 + u * (p3 + u * (p4 + u * p5)))),
        q0 + u * (q1 + u * (q2 + u * (q3 + u * q4))),
        r0 + u * (r1 + u * (r2 + u * r3)),
        s0 + u * (s1 + u * s2),
        t0 + u * t1,
    )


def flat_layout(a: NDArray[np.float64], orders: int) -> list[tuple[float, ...]]:
    """Per row of ``a`` (coefficients of sum_k a[k] u^k), the coefficients of the polynomial and of
    its derivatives up to ``orders - 1``, back to back: order d contributes a[j + d] (j + d)!/j!,
    j = 0..deg-d. Horner then needs no multiplications by constants (a quintic with orders = 5 gives
    6 + 5 + 4 + 3 + 2 numbers)."""
    n = a.shape[1]
    src = [j + d for d in range(orders) for j in range(n - d)]
    mult = np.array([perm(j + d, d) for d in range(orders) for j in range(n - d)], dtype=float)
    return [tuple(row) for row in (a[:, src] * mult).tolist()]


def interval(breaks: list[float], n: int, lam: float) -> int:
    """Index of the interval [breaks[i], breaks[i+1]) holding lam; the end intervals extend
    beyond the ends (``n`` = number of intervals)."""
    i = bisect_right(breaks, lam) - 1
    return 0 if i < 0 else (n - 1 if i >= n else i)


def horner2_xyz(c: tuple[tuple[float, ...], ...], u: float) -> tuple[float, ...]:
    """Orders 0..2 of three axes' flat tuples at u: (x, y, z, x', y', z', x'', y'', z'')."""
    x = _horner2(c[0], u)
    y = _horner2(c[1], u)
    z = _horner2(c[2], u)
    return (x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2])


def _horner2(c: tuple[float, ...], u: float) -> tuple[float, float, float]:
    """Orders 0..2 only (see :func:`_horner4`); ``c`` may be the 15-long head of the layout."""
    p0, p1, p2, p3, p4, p5, q0, q1, q2, q3, q4, r0, r1, r2, r3 = c[:15]
    return (
        p0 + u * (p1 + u * (p2 + u * (p3 + u * (p4 + u * p5)))),
        q0 + u * (q1 + u * (q2 + u * (q3 + u * q4))),
        r0 + u * (r1 + u * (r2 + u * r3)),
    )
