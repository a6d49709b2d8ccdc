"""Moving frames along the path: Frenet-Serret (eq. 8) and rotation-minimising (parallel transport).

Both return the frame jet ``(t, e2, e3)`` with exact first and second derivatives with respect to
the path parameter lambda, as float tuples (see :mod:`pf_offboard.path._vec`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pf_offboard.path._vec import Jet, cross_jet, reject_jet, unit_jet
from pf_offboard.path.spline import QuinticSpline, flat_layout, horner2_xyz, interval


def tangent_jet(s: tuple[float, ...]) -> Jet:
    """``t = sigma'/|sigma'|`` with derivatives, from the 15-float spline jet ``s``."""
    return unit_jet((s[3], s[4], s[5]), (s[6], s[7], s[8]), (s[9], s[10], s[11]))


def frenet_jets(s: tuple[float, ...]) -> tuple[Jet, Jet, Jet]:
    """Frenet-Serret ``(t, p, b)`` jets from sigma..sigma'''' (15 floats).

    ``t = unit(sigma')``; ``p = unit(w)`` with ``w = sigma'' - <sigma'', t> t`` (the component of
    sigma'' orthogonal to sigma', the direction of t'); ``b = t x p``. p'' needs sigma''''.
    """
    t = tangent_jet(s)
    p = unit_jet(*reject_jet(((s[6], s[7], s[8]), (s[9], s[10], s[11]), (s[12], s[13], s[14])), t))
    return t, p, cross_jet(t, p)


def _unit_rows(w: NDArray[np.float64], w1: NDArray[np.float64], w2: NDArray[np.float64]):
    """Vectorised :func:`unit_jet` over rows (build-time)."""
    n = np.linalg.norm(w, axis=1)[:, None]
    u = w / n
    n1 = np.sum(u * w1, axis=1)[:, None]
    u1 = (w1 - n1 * u) / n
    n2 = (np.sum(u1 * w1, axis=1) + np.sum(u * w2, axis=1))[:, None]
    u2 = (w2 - n2 * u - 2.0 * n1 * u1) / n
    return u, u1, u2


def _dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.sum(a * b, axis=1)[:, None]


def initial_normal(t0: NDArray[np.float64]) -> NDArray[np.float64]:
    """Start vector e2 at lambda = 0: e3 = world up made orthogonal to t, e2 = e3 x t.

    For a horizontal tangent this puts e2 to the left (horizontal) and e3 up. If the tangent is
    (nearly) vertical, world x takes the role of "up".
    """
    up = np.array([0.0, 0.0, 1.0])
    if abs(float(np.dot(up, t0))) > 0.9:
        up = np.array([1.0, 0.0, 0.0])
    e3 = up - np.dot(up, t0) * t0
    e3 /= np.linalg.norm(e3)
    e2 = np.cross(e3, t0)
    return e2 / np.linalg.norm(e2)


def _hermite_quintic(h: NDArray[np.float64], y0, d0, dd0, y1, d1, dd1) -> NDArray[np.float64]:
    """Coefficients a0..a5 (shape (n, 6, 3)) of the quintic on [0, h] matching value, first and
    second derivative at both ends (local variable v = lambda - left node)."""
    hh = h[:, None]
    a0, a1, a2 = y0, d0, 0.5 * dd0
    big_a = y1 - (a0 + a1 * hh + a2 * hh**2)
    big_b = d1 - (a1 + 2.0 * a2 * hh)
    big_c = dd1 - 2.0 * a2
    a3 = (10.0 * big_a - 4.0 * big_b * hh + 0.5 * big_c * hh**2) / hh**3
    a4 = (-15.0 * big_a + 7.0 * big_b * hh - big_c * hh**2) / hh**4
    a5 = (6.0 * big_a - 3.0 * big_b * hh + 0.5 * big_c * hh**2) / hh**5
    return np.stack([a0, a1, a2, a3, a4, a5], axis=1)


def _double_reflection(pos: NDArray[np.float64], t: NDArray[np.float64], e0: NDArray[np.float64]) -> NDArray[np.float64]:
    """Transported normal at every node (Wang et al. 2008): reflect (e, t) in the bisector plane of
    the chord, then in the plane that maps the reflected tangent onto the next tangent."""
    v1 = np.diff(pos, axis=0)
    k1 = 2.0 / np.sum(v1 * v1, axis=1)
    t_l = t[:-1] - (k1 * np.sum(v1 * t[:-1], axis=1))[:, None] * v1
    v2 = t[1:] - t_l
    c2 = np.sum(v2 * v2, axis=1)
    # c2 = 0: the tangent does not turn (straight piece), the second reflection is the identity.
    k2 = np.where(c2 > 1e-30, 2.0 / np.where(c2 > 1e-30, c2, 1.0), 0.0)
    rows = zip(v1.tolist(), k1.tolist(), v2.tolist(), k2.tolist(), t[1:].tolist())
    ex, ey, ez = (float(v) for v in e0)
    out = [(ex, ey, ez)]
    for (ax, ay, az), ka, (bx, by, bz), kb, (tx, ty, tz) in rows:
        f = ka * (ax * ex + ay * ey + az * ez)
        ex, ey, ez = ex - f * ax, ey - f * ay, ez - f * az
        f = kb * (bx * ex + by * ey + bz * ez)
        ex, ey, ez = ex - f * bx, ey - f * by, ez - f * bz
        # Remove the rounding drift off the normal plane and off unit length.
        f = ex * tx + ey * ty + ez * tz
        ex, ey, ez = ex - f * tx, ey - f * ty, ez - f * tz
        f = 1.0 / math.sqrt(ex * ex + ey * ey + ez * ez)
        ex, ey, ez = ex * f, ey * f, ez * f
        out.append((ex, ey, ez))
    return np.array(out)


class RotationMinimisingFrame:
    """Rotation-minimising (parallel-transport) normal field e2 with exact derivatives.

    Construction: the transported normal is integrated on a fine grid with the double-reflection
    method (Wang et al. 2008, 4th order). At each node the exact transport law gives
    ``e' = -<e, t'> t`` and ``e'' = -<e, t''> t - <e, t'> t'``; between nodes ``e_hat`` is the quintic
    Hermite interpolant of (e, e', e''). The frame returned is ``e2 = unit(e_hat - <e_hat, t> t)``,
    whose derivatives follow exactly by the chain rule, so e2, e2', e2'' are mutually consistent to
    rounding while e2 stays unit and orthogonal to t. For closed paths the holonomy twist Delta is
    distributed linearly: the node data are rotated about t by ``theta = -Delta lam / lam_max`` so the
    frame closes with C2 continuity; then ``<e2', e3> = theta' = -Delta / lam_max`` everywhere.
    """

    def __init__(self, spline: QuinticSpline, nodes: NDArray[np.float64]) -> None:
        lam = nodes
        d1 = spline.eval_vectorised(lam, 1)
        d2 = spline.eval_vectorised(lam, 2)
        d3 = spline.eval_vectorised(lam, 3)
        pos = spline.eval_vectorised(lam, 0)
        t, t1, t2 = _unit_rows(d1, d2, d3)
        n = len(lam)
        e = _double_reflection(pos, t, initial_normal(t[0]))
        e1 = -_dot(e, t1) * t
        e2 = -_dot(e, t2) * t - _dot(e, t1) * t1
        self.twist_rate = 0.0
        self.holonomy_rad = 0.0
        if spline.closed:
            # Angle from e[0] to the transported e[-1] about t[0] (= t[-1]).
            f0 = np.cross(t[0], e[0])
            delta = math.atan2(float(e[-1] @ f0), float(e[-1] @ e[0]))
            self.holonomy_rad = delta
            th1 = -delta / spline.lam_max
            th = (th1 * lam)[:, None]
            f = np.cross(t, e)
            f1 = np.cross(t1, e) + np.cross(t, e1)
            f2 = np.cross(t2, e) + 2.0 * np.cross(t1, e1) + np.cross(t, e2)
            c, s = np.cos(th), np.sin(th)
            g = c * e + s * f
            g1 = c * e1 + s * f1 + th1 * (-s * e + c * f)
            g2 = c * e2 + s * f2 + 2.0 * th1 * (-s * e1 + c * f1) - th1 * th1 * g
            # The last node is the first one again: make the seam exactly periodic.
            g[-1], g1[-1], g2[-1] = g[0], g1[0], g2[0]
            e, e1, e2 = g, g1, g2
            self.twist_rate = th1
        coef = _hermite_quintic(np.diff(lam), e[:-1], e1[:-1], e2[:-1], e[1:], e1[1:], e2[1:])
        self._nodes = [float(v) for v in lam]
        self._nint = n - 1
        # Per interval and axis, the spline's flat layout for orders 0..2 (what horner2_xyz reads).
        flat = list(zip(*(flat_layout(coef[:, :, ax], 3) for ax in range(3))))
        self._flat = flat

    def normal_jet(self, lam: float, t: Jet) -> Jet:
        """e2 jet at ``lam`` (in range) given the tangent jet there."""
        i = interval(self._nodes, self._nint, lam)
        h = horner2_xyz(self._flat[i], lam - self._nodes[i])
        ehat = ((h[0], h[1], h[2]), (h[3], h[4], h[5]), (h[6], h[7], h[8]))
        return unit_jet(*reject_jet(ehat, t))

    def jets(self, s: tuple[float, ...], lam: float) -> tuple[Jet, Jet, Jet]:
        """``(t, e2, e3)`` jets at ``lam`` from the 15-float spline jet ``s`` there."""
        t = tangent_jet(s)
        e2 = self.normal_jet(lam, t)
        return t, e2, cross_jet(t, e2)

