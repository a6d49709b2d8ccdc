"""The path at N parameters at once (mirrors :mod:`pf_offboard.path.path`, ``spline``,
``moving_frame`` and ``_vec``). Vectors are tuples of three ``(N,)`` arrays."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

Arr = NDArray[np.float64]
V = tuple[Arr, Arr, Arr]
Jet = tuple[V, V, V]


def interval(breaks: Arr, n: int, lam: Arr) -> NDArray[np.intp]:
    """:func:`pf_offboard.path.spline.interval` at many parameters."""
    i = np.searchsorted(breaks, lam, side="right") - 1
    return np.minimum(np.maximum(i, 0), n - 1)  # np.clip's, without its per-call dtype checks


class BatchPath:
    """Arrays of a :class:`pf_offboard.path.Path` for evaluation at many parameters."""

    def __init__(self, path: Any) -> None:
        self.path = path
        sp = path._spline
        self.closed = bool(path.closed)
        self.lam_max = float(path.lam_max)
        self.length_m = float(path.length_m)
        self._knots = np.array(sp._knot_list)
        self._nseg = sp._nseg
        self._centres = np.array(sp._centres)
        # (nseg, 3 axes, 20): the flat layout of pf_offboard.path.spline (orders 0..4 back to back)
        self._flat = np.array([[list(c) for c in seg] for seg in sp._flat])
        self._grid = np.array(path._grid_list)
        self._ngrid = path._ngrid
        self._cum = np.array(path._cum)
        ncoef = len(path._arc_coef[0])
        self._arc_coef = np.array(path._arc_coef).reshape(-1, ncoef)
        self._half_h = np.array(path._half_h)
        rmf = path._rmf
        self.rmf = rmf is not None
        if rmf is not None:
            self._nodes = np.array(rmf._nodes)
            self._nint = rmf._nint
            self._rflat = np.array([[list(c) for c in seg] for seg in rmf._flat])

    # ------------------------------------------------------------------ parameter handling
    def inrange(self, lam: Arr) -> Arr:
        """``Path._inrange``: closed paths periodic, open ones unchanged."""
        if not self.closed:
            return lam
        out = np.where((lam >= 0.0) & (lam < self.lam_max), lam, np.mod(lam, self.lam_max))
        return np.where(out >= self.lam_max, 0.0, out)

    def wrap(self, lam: Arr) -> Arr:
        """``Path.wrap``."""
        if self.closed:
            r = np.mod(lam, self.lam_max)
            return np.where(r >= self.lam_max, 0.0, r)
        return np.where(lam < 0.0, 0.0, np.where(lam > self.lam_max, self.lam_max, lam))

    # ------------------------------------------------------------------ geometry
    def eval_floats(self, lam: Arr) -> tuple[Arr, ...]:
        """``Path.eval_floats``: 15 arrays (x, y, z per order 0..4)."""
        lam = self.inrange(lam)
        i = interval(self._knots, self._nseg, lam)
        u = lam - self._centres[i]
        c = self._flat[i]  # (N, 3, 20)
        h = _horner4(c.T, u)  # the three axes at once: (3 axes, N) per order
        return (h[0][0], h[0][1], h[0][2], h[1][0], h[1][1], h[1][2], h[2][0], h[2][1], h[2][2], h[3][0], h[3][1], h[3][2],
                h[4][0], h[4][1], h[4][2])  # fmt: skip

    def eval2_floats(self, lam: Arr) -> tuple[Arr, ...]:
        """``QuinticSpline.eval2_floats`` (not wrapped): 9 arrays."""
        i = interval(self._knots, self._nseg, lam)
        u = lam - self._centres[i]
        h = _horner2(self._flat[i].T, u)  # (3 axes, N) per order
        return (h[0][0], h[0][1], h[0][2], h[1][0], h[1][1], h[1][2], h[2][0], h[2][1], h[2][2])

    def frame_jets(self, lam: Arr, s: tuple[Arr, ...]) -> tuple[Jet, Jet, Jet]:
        """``Path.frame_jets`` given ``s = eval_floats(lam)``."""
        t = unit_jet((s[3], s[4], s[5]), (s[6], s[7], s[8]), (s[9], s[10], s[11]))
        if not self.rmf:
            p = unit_jet(*reject_jet(((s[6], s[7], s[8]), (s[9], s[10], s[11]), (s[12], s[13], s[14])), t))
            return t, p, cross_jet(t, p)
        lam = self.inrange(lam)
        i = interval(self._nodes, self._nint, lam)
        u = lam - self._nodes[i]
        h = _horner2(self._rflat[i].T, u)  # (3 axes, N) per order
        ehat = ((h[0][0], h[0][1], h[0][2]), (h[1][0], h[1][1], h[1][2]), (h[2][0], h[2][1], h[2][2]))
        e2 = unit_jet(*reject_jet(ehat, t))
        return t, e2, cross_jet(t, e2)

    def arclength(self, lam: Arr) -> Arr:
        """``Path.arclength``."""
        lam = self.wrap(lam)
        i = interval(self._grid, self._ngrid, lam)
        x = (lam - self._grid[i]) / self._half_h[i] - 1.0
        coef = self._arc_coef[i]
        v = np.zeros_like(lam)
        for k in range(coef.shape[1]):
            v = v * x + coef[:, k]
        return self._cum[i] + v


def _horner4(c: Arr, u: Arr) -> list[Arr]:
    p0, p1, p2, p3, p4, p5, q0, q1, q2, q3, q4, r0, r1, r2, r3, s0, s1, s2, t0, t1 = c
    return [
        p0 + u * (p1 + u * (p2 + u * (p3 + u * (p4 + u * p5)))),
        q0 + u * (q1 + u * (q2 + u * (q3 + u * q4))),
        r0 + u * (r1 + u * (r2 + u * r3)),
        s0 + u * (s1 + u * s2),
        t0 + u * t1,
    ]


def _horner2(c: Arr, u: Arr) -> list[Arr]:
    p0, p1, p2, p3, p4, p5, q0, q1, q2, q3, q4, r0, r1, r2, r3 = c[:15]
    return [
        p0 + u * (p1 + u * (p2 + u * (p3 + u * (p4 + u * p5)))),
        q0 + u * (q1 + u * (q2 + u * (q3 + u * q4))),
        r0 + u * (r1 + u * (r2 + u * r3)),
    ]


def unit_jet(w: V, w1: V, w2: V) -> Jet:
    """:func:`pf_offboard.path._vec.unit_jet`."""
    wx, wy, wz = w
    ax, ay, az = w1
    bx, by, bz = w2
    inv = 1.0 / np.sqrt(wx * wx + wy * wy + wz * wz)
    ux = wx * inv
    uy = wy * inv
    uz = wz * inv
    n1 = ux * ax + uy * ay + uz * az
    u1x = (ax - n1 * ux) * inv
    u1y = (ay - n1 * uy) * inv
    u1z = (az - n1 * uz) * inv
    n2 = u1x * ax + u1y * ay + u1z * az + ux * bx + uy * by + uz * bz
    n1 = n1 * 2.0
    return (
        (ux, uy, uz),
        (u1x, u1y, u1z),
        ((bx - n2 * ux - n1 * u1x) * inv, (by - n2 * uy - n1 * u1y) * inv, (bz - n2 * uz - n1 * u1z) * inv),
    )


def reject_jet(v: Jet, t: Jet) -> Jet:
    """:func:`pf_offboard.path._vec.reject_jet`."""
    (vx, vy, vz), (v1x, v1y, v1z), (v2x, v2y, v2z) = v
    (tx, ty, tz), (t1x, t1y, t1z), (t2x, t2y, t2z) = t
    c = vx * tx + vy * ty + vz * tz
    c1 = v1x * tx + v1y * ty + v1z * tz + vx * t1x + vy * t1y + vz * t1z
    c2 = (
        v2x * tx + v2y * ty + v2z * tz
        + 2.0 * (v1x * t1x + v1y * t1y + v1z * t1z)
        + vx * t2x + vy * t2y + vz * t2z
    )  # fmt: skip
    k1 = 2.0 * c1
    return (
        (vx - c * tx, vy - c * ty, vz - c * tz),
        (v1x - c1 * tx - c * t1x, v1y - c1 * ty - c * t1y, v1z - c1 * tz - c * t1z),
        (
            v2x - c2 * tx - k1 * t1x - c * t2x,
            v2y - c2 * ty - k1 * t1y - c * t2y,
            v2z - c2 * tz - k1 * t1z - c * t2z,
        ),
    )


def cross_jet(a: Jet, b: Jet) -> Jet:
    """:func:`pf_offboard.path._vec.cross_jet`."""
    (ax, ay, az), (a1x, a1y, a1z), (a2x, a2y, a2z) = a
    (bx, by, bz), (b1x, b1y, b1z), (b2x, b2y, b2z) = b
    return (
        (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx),
        (
            a1y * bz - a1z * by + ay * b1z - az * b1y,
            a1z * bx - a1x * bz + az * b1x - ax * b1z,
            a1x * by - a1y * bx + ax * b1y - ay * b1x,
        ),
        (
            a2y * bz - a2z * by + 2.0 * (a1y * b1z - a1z * b1y) + ay * b2z - az * b2y,
            a2z * bx - a2x * bz + 2.0 * (a1z * b1x - a1x * b1z) + az * b2x - ax * b2z,
            a2x * by - a2y * bx + 2.0 * (a1x * b1y - a1y * b1x) + ax * b2y - ay * b2x,
        ),
    )


# ---------------------------------------------------------------------------------- libm parity
# NumPy's hypot, pow, atan2, acos, asin and exp may differ from Python's math module in the last
# bit; the batch must round exactly like the scalar code (a bisection step or a saturation test
# decided by one ulp would otherwise make flights drift apart), so these go through math per
# element (~0.1 us each: a few calls per control step).
def hypot(a: Arr, b: Arr) -> Arr:
    import math

    return np.fromiter(map(math.hypot, a.tolist(), b.tolist()), float, count=a.size).reshape(a.shape)


def power(a: Arr, e: float) -> Arr:
    return np.fromiter(map(pow, a.tolist(), [e] * a.size), float, count=a.size).reshape(a.shape)


def atan2(y: Arr, x: Arr) -> Arr:
    import math

    return np.fromiter(map(math.atan2, y.tolist(), x.tolist()), float, count=y.size).reshape(y.shape)


def unary(fn: object, a: Arr) -> Arr:
    return np.fromiter(map(fn, a.tolist()), float, count=a.size).reshape(a.shape)  # type: ignore[call-overload]
