"""The set of mass-normalised thrust vectors the vehicle may be commanded (convex).

``F = { f : f_z >= T_min, |f| <= T_max, |f_h| <= tan(tilt) f_z }`` with ``f = a + g e_z``.
``f_z >= T_min`` is used for the minimum-thrust bound because it keeps F convex and implies
``|f| >= T_min``. Convexity matters: a segment between feasible commands stays feasible (blending)
and the feasible part of a line is one interval (priority allocation).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

Vec = tuple[float, float, float]
Arr = NDArray[np.float64]
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

    def contains_each(self, fx: Arr, fy: Arr, fz: Arr, tol: float = 1e-9) -> NDArray[np.bool_]:
        """:meth:`contains` for many vectors (component arrays), with ``math.hypot`` as there: the
        same verdicts."""
        h = np.fromiter(map(math.hypot, fx.tolist(), fy.tolist()), float, len(fx))
        return (fz >= self.min_thrust_m_s2 - tol) & (fx * fx + fy * fy + fz * fz <= (self.max_thrust_m_s2 + tol) ** 2) & (h <= self.tan_tilt * fz + tol)

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

    def line_intervals(self, f0: tuple[Arr, Arr, Arr], m: tuple[Arr, Arr, Arr]) -> tuple[Arr, Arr, NDArray[np.bool_]]:
        """:meth:`line_interval` for many lines at once (component arrays of equal shape):
        ``(lo, hi, empty)``, ``empty`` where the scalar gives None (lo, hi are then meaningless).
        The same operations in the same order, so the bounds equal the scalar's bit for bit."""
        with np.errstate(all="ignore"):
            return self._line_intervals(f0, m)

    def _line_intervals(self, f0: tuple[Arr, Arr, Arr], m: tuple[Arr, Arr, Arr]) -> tuple[Arr, Arr, NDArray[np.bool_]]:
        fx, fy, fz = f0
        mx, my, mz = m
        lo = np.full(np.shape(fz), -_INF)
        hi = np.full(np.shape(fz), _INF)
        gap = self.min_thrust_m_s2 - fz
        q = gap / mz
        lo = np.where(mz > 0.0, q, lo)
        hi = np.where(mz < 0.0, q, hi)
        empty = (mz == 0.0) & (gap > 0.0)
        # |f0 + s m|^2 <= T_max^2
        a = mx * mx + my * my + mz * mz
        b = fx * mx + fy * my + fz * mz
        c = fx * fx + fy * fy + fz * fz - self.max_thrust_m_s2 * self.max_thrust_m_s2
        flat = a <= 0.0
        empty |= flat & (c > 0.0)
        disc = b * b - a * c
        empty |= ~flat & (disc < 0.0)
        use = ~flat & (disc >= 0.0)
        r1, r2 = _roots_v(a, b, c, np.sqrt(disc))
        lo = np.where(use, _max(lo, r1), lo)
        hi = np.where(use, _min(hi, r2), hi)
        # the tilt cone
        t2 = self.tan_tilt * self.tan_tilt
        a = t2 * mz * mz - (mx * mx + my * my)
        b = t2 * fz * mz - (fx * mx + fy * my)
        c = t2 * fz * fz - (fx * fx + fy * fy)
        aa, ab, ac = np.abs(a), np.abs(b), np.abs(c)
        scale = _max(_max(_max(aa, ab), ac), np.full(np.shape(a), 1e-300))
        lin = aa <= 1e-14 * scale
        root = -c / (2.0 * b)
        lo = np.where(lin & (b > 0.0), _max(lo, root), lo)
        hi = np.where(lin & (b < 0.0), _min(hi, root), hi)
        empty |= lin & (b == 0.0) & (c < 0.0)
        disc = b * b - a * c
        cross = ~lin & (a < 0.0)
        empty |= cross & (disc < 0.0)
        inside = ~lin & (a > 0.0) & (disc > 0.0)
        r1, r2 = _roots_v(a, b, c, np.sqrt(disc))
        c_use = cross & (disc >= 0.0)
        lo = np.where(c_use, _max(lo, r1), lo)
        hi = np.where(c_use, _min(hi, r2), hi)
        up = mz > 0.0
        lo = np.where(inside & up, _max(lo, r2), lo)
        hi = np.where(inside & ~up, _min(hi, r1), hi)
        empty |= lo > hi
        return lo, hi, empty

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


def _max(x: Arr, y: Arr) -> Arr:
    """Python's ``max(x, y)`` elementwise (y only where it is greater: keeps x's sign of zero)."""
    return np.where(y > x, y, x)


def _min(x: Arr, y: Arr) -> Arr:
    """Python's ``min(x, y)`` elementwise."""
    return np.where(y < x, y, x)


def _roots_v(a: Arr, b: Arr, c: Arr, sq: Arr) -> tuple[Arr, Arr]:
    """:func:`_roots` elementwise."""
    q = np.where(b >= 0.0, -(b + sq), -(b - sq))
    zero = q == 0.0
    r1 = q / a
    r2 = c / q
    swap = ~(r1 <= r2)
    lo = np.where(swap, r2, r1)
    hi = np.where(swap, r1, r2)
    return np.where(zero, 0.0, lo), np.where(zero, 0.0, hi)
