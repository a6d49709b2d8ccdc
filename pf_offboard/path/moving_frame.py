"""Moving frames along the path: Frenet-Serret (eq. 8) and rotation-minimising (parallel transport).

Both return the frame jet ``(t, e2, e3)`` with exact first and second derivatives with respect to
the path parameter lambda, as float tuples (see :mod:`pf_offboard.path._vec`).
"""

from __future__ import annotations

import math
from bisect import bisect_right

import numpy as np
from numpy.typing import NDArray

from pf_offboard.path._vec import Jet, cross_jet, reject_jet, unit_jet
from pf_offboard.path.spline import QuinticSpline


def tangent_jet(s: tuple[float, ...]) -> Jet:
    """``t = sigma'/|sigma'|`` with derivatives, from the 15-float spline jet ``s``."""
    return unit_jet((s[3], s[4], s[5]), (s[6], s[7], s[8]), (s[9], s[10], s[11]))


def frenet_jets(s: tuple[float, ...]) -> tuple[Jet, Jet, Jet]:
    """Frenet-Serret ``(t, p, b)`` jets from sigma..sigma'''' (15 floats).

    ``t = unit(sigma')``; ``p = unit(w)`` with ``w = sigma'' - <sigma'', t> t`` (the component of
    sigma'' orthogonal to sigma', same direction as t'); ``b = t x p``. The rules are those of
    :func:`unit_jet`, :func:`reject_jet` and :func:`cross_jet` (see :func:`frenet_jets_reference`),
    fused into straight-line code because this runs every control step. p'' needs sigma''''.
    """
    _, _, _, ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz = s
    # t = unit(sigma'): n' = <t, sigma''>, n'' = <t', sigma''> + <t, sigma'''>.
    inv = 1.0 / math.sqrt(ax * ax + ay * ay + az * az)
    tx, ty, tz = ax * inv, ay * inv, az * inv
    n1 = tx * bx + ty * by + tz * bz
    t1x, t1y, t1z = (bx - n1 * tx) * inv, (by - n1 * ty) * inv, (bz - n1 * tz) * inv
    n2 = t1x * bx + t1y * by + t1z * bz + tx * cx + ty * cy + tz * cz
    k = 2.0 * n1
    t2x = (cx - n2 * tx - k * t1x) * inv
    t2y = (cy - n2 * ty - k * t1y) * inv
    t2z = (cz - n2 * tz - k * t1z) * inv
    # w = sigma'' - c t: c = <sigma'', t> = n1, c' = n2, c'' = <sigma'''', t> + 2<sigma''', t'> + <sigma'', t''>.
    c2 = dx * tx + dy * ty + dz * tz + 2.0 * (cx * t1x + cy * t1y + cz * t1z) + bx * t2x + by * t2y + bz * t2z
    k = 2.0 * n2
    wx, wy, wz = bx - n1 * tx, by - n1 * ty, bz - n1 * tz
    w1x, w1y, w1z = cx - n2 * tx - n1 * t1x, cy - n2 * ty - n1 * t1y, cz - n2 * tz - n1 * t1z
    w2x = dx - c2 * tx - k * t1x - n1 * t2x
    w2y = dy - c2 * ty - k * t1y - n1 * t2y
    w2z = dz - c2 * tz - k * t1z - n1 * t2z
    # p = unit(w).
    inv = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)
    px, py, pz = wx * inv, wy * inv, wz * inv
    m1 = px * w1x + py * w1y + pz * w1z
    p1x, p1y, p1z = (w1x - m1 * px) * inv, (w1y - m1 * py) * inv, (w1z - m1 * pz) * inv
    m2 = p1x * w1x + p1y * w1y + p1z * w1z + px * w2x + py * w2y + pz * w2z
    k = 2.0 * m1
    p2x = (w2x - m2 * px - k * p1x) * inv
    p2y = (w2y - m2 * py - k * p1y) * inv
    p2z = (w2z - m2 * pz - k * p1z) * inv
    # b = t x p and the product rule.
    return (
        ((tx, ty, tz), (t1x, t1y, t1z), (t2x, t2y, t2z)),
        ((px, py, pz), (p1x, p1y, p1z), (p2x, p2y, p2z)),
        (
            (ty * pz - tz * py, tz * px - tx * pz, tx * py - ty * px),
            (
                t1y * pz - t1z * py + ty * p1z - tz * p1y,
                t1z * px - t1x * pz + tz * p1x - tx * p1z,
                t1x * py - t1y * px + tx * p1y - ty * p1x,
            ),
            (
                t2y * pz - t2z * py + 2.0 * (t1y * p1z - t1z * p1y) + ty * p2z - tz * p2y,
                t2z * px - t2x * pz + 2.0 * (t1z * p1x - t1x * p1z) + tz * p2x - tx * p2z,
                t2x * py - t2y * px + 2.0 * (t1x * p1y - t1y * p1x) + tx * p2y - ty * p2x,
            ),
        ),
    )


def frenet_jets_reference(s: tuple[float, ...]) -> tuple[Jet, Jet, Jet]:
    """:func:`frenet_jets` composed from the generic jet rules (slower; the tests compare both)."""
    t = tangent_jet(s)
    w = reject_jet(((s[6], s[7], s[8]), (s[9], s[10], s[11]), (s[12], s[13], s[14])), t)
    p = unit_jet(*w)
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
        e = np.empty((n, 3))
        e[0] = initial_normal(t[0])
        for j in range(n - 1):
            # Double reflection: reflect (e, t) in the bisector plane of the chord, then in the plane
            # that maps the reflected tangent onto the next tangent.
            v1 = pos[j + 1] - pos[j]
            c1 = float(v1 @ v1)
            r_l = e[j] - (2.0 / c1) * float(v1 @ e[j]) * v1
            t_l = t[j] - (2.0 / c1) * float(v1 @ t[j]) * v1
            v2 = t[j + 1] - t_l
            c2 = float(v2 @ v2)
            r = r_l - (2.0 / c2) * float(v2 @ r_l) * v2 if c2 > 1e-30 else r_l
            r -= float(r @ t[j + 1]) * t[j + 1]
            e[j + 1] = r / np.linalg.norm(r)
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
        # Per interval and axis: (a0..a5, first-derivative coefs 1..5 scaled, second 2..5 scaled).
        flat = []
        for i in range(n - 1):
            per_axis = []
            for ax in range(3):
                a = [float(v) for v in coef[i, :, ax]]
                per_axis.append(
                    (
                        *a,
                        a[1], 2 * a[2], 3 * a[3], 4 * a[4], 5 * a[5],
                        2 * a[2], 6 * a[3], 12 * a[4], 20 * a[5],
                    )
                )
            flat.append(tuple(per_axis))
        self._flat = flat

    def normal_jet(self, lam: float, t: Jet) -> Jet:
        """e2 jet at ``lam`` (in range) given the tangent jet there."""
        i = bisect_right(self._nodes, lam) - 1
        if i < 0:
            i = 0
        elif i >= self._nint:
            i = self._nint - 1
        v = lam - self._nodes[i]
        hx = _h2(self._flat[i][0], v)
        hy = _h2(self._flat[i][1], v)
        hz = _h2(self._flat[i][2], v)
        ehat = ((hx[0], hy[0], hz[0]), (hx[1], hy[1], hz[1]), (hx[2], hy[2], hz[2]))
        return unit_jet(*reject_jet(ehat, t))

    def jets(self, s: tuple[float, ...], lam: float) -> tuple[Jet, Jet, Jet]:
        """``(t, e2, e3)`` jets at ``lam`` from the 15-float spline jet ``s`` there."""
        t = tangent_jet(s)
        e2 = self.normal_jet(lam, t)
        return t, e2, cross_jet(t, e2)


def _h2(c: tuple[float, ...], v: float) -> tuple[float, float, float]:
    a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, c0, c1, c2, c3 = c
    return (
        a0 + v * (a1 + v * (a2 + v * (a3 + v * (a4 + v * a5)))),
        b0 + v * (b1 + v * (b2 + v * (b3 + v * b4))),
        c0 + v * (c1 + v * (c2 + v * c3)),
    )
