"""The set of mass-normalised thrust vectors the vehicle may be commanded (convex).

``F = { f : f_z >= T_min, |f| <= T_max, |f_h| <= tan(tilt) f_z }`` with ``f = a + g e_z``.
``f_z >= T_min`` is used for the minimum-thrust bound because it keeps F convex and implies
``|f| >= T_min``. Convexity matters: a segment between feasible commands stays feasible (blending)
and the feasible part of a line is one interval (priority allocation).
"""

from __future__ import annotations

import math
from typing import NamedTuple

Vec = tuple[float, float, float]
_INF = math.inf


class ThrustSet(NamedTuple):
    min_thrust_m_s2: float
    max_thrust_m_s2: float
    tan_tilt: float

    def contains(self, f: Vec, tol: float = 1e-9) -> bool:
        fx, fy, fz = f
        return (
            fz >= self.min_thrust_m_s2 - tol
            and fx * fx + fy * fy + fz * fz <= (self.max_thrust_m_s2 + tol) ** 2
            and math.hypot(fx, fy) <= self.tan_tilt * fz + tol
        )

    def active(self, f: Vec, rel: float = 1e-6) -> tuple[bool, bool]:
        """(tilt, thrust): is f on the tilt cone / on a thrust bound (within ``rel``)."""
        fx, fy, fz = f
        tol = rel * self.max_thrust_m_s2
        tilt = math.hypot(fx, fy) >= self.tan_tilt * fz - tol
        thrust = fz <= self.min_thrust_m_s2 + tol or math.sqrt(fx * fx + fy * fy + fz * fz) >= self.max_thrust_m_s2 - tol
        return tilt, thrust

    def line_interval(self, f0: Vec, m: Vec) -> tuple[float, float] | None:
        """``{s : f0 + s m in F}`` as ``(lo, hi)`` (possibly infinite), or None if empty."""
        lo, hi = -_INF, _INF
        # f_z >= T_min (linear)
        mz = m[2]
        gap = self.min_thrust_m_s2 - f0[2]
        if mz > 0.0:
            lo = gap / mz
        elif mz < 0.0:
            hi = gap / mz
        elif gap > 0.0:
            return None
        # |f0 + s m|^2 <= T_max^2
        a = m[0] * m[0] + m[1] * m[1] + mz * mz
        b = f0[0] * m[0] + f0[1] * m[1] + f0[2] * mz  # half of the linear coefficient
        c = f0[0] * f0[0] + f0[1] * f0[1] + f0[2] * f0[2] - self.max_thrust_m_s2 * self.max_thrust_m_s2
        if a <= 0.0:
            if c > 0.0:
                return None
        else:
            disc = b * b - a * c
            if disc < 0.0:
                return None
            sq = math.sqrt(disc)
            r1, r2 = _roots(a, b, c, sq)
            lo = max(lo, r1)
            hi = min(hi, r2)
        # tan^2 f_z^2 - |f_h|^2 >= 0 on the upper nappe (f_z >= T_min >= 0 is already imposed)
        t2 = self.tan_tilt * self.tan_tilt
        a = t2 * mz * mz - (m[0] * m[0] + m[1] * m[1])
        b = t2 * f0[2] * mz - (f0[0] * m[0] + f0[1] * m[1])
        c = t2 * f0[2] * f0[2] - (f0[0] * f0[0] + f0[1] * f0[1])
        scale = max(abs(a), abs(b), abs(c), 1e-300)
        if abs(a) <= 1e-14 * scale:
            # linear: 2 b s + c >= 0
            if b > 0.0:
                lo = max(lo, -c / (2.0 * b))
            elif b < 0.0:
                hi = min(hi, -c / (2.0 * b))
            elif c < 0.0:
                return None
        else:
            disc = b * b - a * c
            if a < 0.0:
                # the line crosses the cone: Q >= 0 between the roots
                if disc < 0.0:
                    return None
                r1, r2 = _roots(a, b, c, math.sqrt(disc))
                lo = max(lo, r1)
                hi = min(hi, r2)
            elif disc > 0.0:
                # the line runs inside the cone's direction: Q >= 0 on two rays, one per nappe
                r1, r2 = _roots(a, b, c, math.sqrt(disc))
                if mz > 0.0:
                    lo = max(lo, r2)
                else:
                    hi = min(hi, r1)
        if lo > hi:
            return None
        return lo, hi

    def clip(self, f: Vec) -> Vec:
        """A feasible thrust vector near ``f`` (keeps its horizontal direction): the last safety net."""
        fx, fy, fz = f
        if not (math.isfinite(fx) and math.isfinite(fy) and math.isfinite(fz)):
            return (0.0, 0.0, max(self.min_thrust_m_s2, min(9.81, self.max_thrust_m_s2)))
        if fz < self.min_thrust_m_s2:
            fz = self.min_thrust_m_s2
        h = math.hypot(fx, fy)
        hmax = self.tan_tilt * fz
        if h > hmax:
            k = hmax / h
            fx *= k
            fy *= k
        n = math.sqrt(fx * fx + fy * fy + fz * fz)
        if n > self.max_thrust_m_s2:
            k = self.max_thrust_m_s2 / n
            fx *= k
            fy *= k
            fz *= k
            if fz < self.min_thrust_m_s2:
                # only if T_max cos(tilt) < T_min (rejected by Limits): prefer lift over tilt
                fz = self.min_thrust_m_s2
                h = math.sqrt(max(self.max_thrust_m_s2**2 - fz * fz, 0.0))
                hh = math.hypot(fx, fy)
                if hh > h:
                    fx *= h / hh
                    fy *= h / hh
        return fx, fy, fz


def _roots(a: float, b: float, c: float, sq: float) -> tuple[float, float]:
    """Sorted roots of ``a s^2 + 2 b s + c`` given ``sq = sqrt(b^2 - a c)`` (cancellation-free)."""
    q = -(b + sq) if b >= 0.0 else -(b - sq)
    if q == 0.0:
        return 0.0, 0.0
    r1 = q / a
    r2 = c / q
    return (r1, r2) if r1 <= r2 else (r2, r1)
