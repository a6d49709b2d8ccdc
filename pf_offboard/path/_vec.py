"""3-vector calculus on plain float tuples (hot path: numpy call overhead would dominate).

A vector and its first two derivatives with respect to the path parameter travel together as a
"jet" ``(v, v', v'')`` of three 3-tuples. Every rule here is exact differentiation.
"""

from __future__ import annotations

import math

Vec = tuple[float, float, float]
Jet = tuple[Vec, Vec, Vec]


def unit_jet(w: Vec, w1: Vec, w2: Vec) -> Jet:
    """``u = w/|w|`` and its exact derivatives from ``w, w', w''``.

    With ``n = |w|``: ``n' = <u, w'>``, ``u' = (w' - n' u)/n``, ``n'' = <u', w'> + <u, w''>``,
    ``u'' = (w'' - n'' u - 2 n' u')/n`` (from differentiating ``w = n u`` twice).
    """
    wx, wy, wz = w
    ax, ay, az = w1
    bx, by, bz = w2
    inv = 1.0 / math.sqrt(wx * wx + wy * wy + wz * wz)
    ux = wx * inv
    uy = wy * inv
    uz = wz * inv
    n1 = ux * ax + uy * ay + uz * az
    u1x = (ax - n1 * ux) * inv
    u1y = (ay - n1 * uy) * inv
    u1z = (az - n1 * uz) * inv
    n2 = u1x * ax + u1y * ay + u1z * az + ux * bx + uy * by + uz * bz
    n1 *= 2.0
    return (
        (ux, uy, uz),
        (u1x, u1y, u1z),
        ((bx - n2 * ux - n1 * u1x) * inv, (by - n2 * uy - n1 * u1y) * inv, (bz - n2 * uz - n1 * u1z) * inv),
    )


def reject_jet(v: Jet, t: Jet) -> Jet:
    """``w = v - <v, t> t`` (component of v orthogonal to the unit vector t) and its derivatives."""
    (vx, vy, vz), (v1x, v1y, v1z), (v2x, v2y, v2z) = v
    (tx, ty, tz), (t1x, t1y, t1z), (t2x, t2y, t2z) = t
    c = vx * tx + vy * ty + vz * tz
    c1 = v1x * tx + v1y * ty + v1z * tz + vx * t1x + vy * t1y + vz * t1z
    c2 = (
        v2x * tx + v2y * ty + v2z * tz
        + 2.0 * (v1x * t1x + v1y * t1y + v1z * t1z)
        + vx * t2x + vy * t2y + vz * t2z
    )
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
    """``a x b`` and its derivatives (product rule)."""
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
