"""Exact transverse coordinates T(x) and decoupling terms alpha(x), beta(x) (eqs. 9-16, made exact).

The paper evaluates ``dlam*/dt`` as ``eta2 / |sigma'|``, which holds only on the path. Here the
rate of the closest point comes from differentiating the closest-point condition
``<sigma'(lam*), y - sigma(lam*)> = 0``::

    lam_dot = N / D,   N = <sigma', v>,   D = |sigma'|^2 - <sigma'', r>,   r = y - sigma(lam*)

so ``d/dt (eta1, xi1, phi1) = (eta2, xi2, phi2)`` and ``d/dt (eta2, xi2, phi2) = alpha + beta a``
hold everywhere ``D > 0`` (the tube; for the Frenet frame ``D = |sigma'|^2 (1 - kappa xi1)``), for
any moving frame (e2, e3) normal to the tangent: Frenet-Serret (p, b) or rotation-minimising.
Derivation in docs/controller.md; proven by finite differences in tests/control/test_transverse.py.

Everything here runs on plain float 3-tuples: it is the controller's hot path.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from pf_offboard.control.types import TransverseState

Vec = tuple[float, float, float]


class ExactTerms(NamedTuple):
    """T(x), alpha(x), beta(x) (rows) at one state, plus the quantities the control law reuses."""

    state: TransverseState
    alpha: Vec
    beta1: Vec
    beta2: Vec
    beta3: Vec
    lam_dot: float  # 1/s, exact rate of the closest-point parameter
    tube: float  # <sigma'', r> / |sigma'|^2: < 1 inside the tube (kappa xi1 for the Frenet frame)
    tangential_offset_m: float  # <t, r>: 0 at a true closest point; not 0 past an open path's end


def exact_terms(
    eta1: float,
    sigma: Vec,
    d1: Vec,
    d2: Vec,
    d3: Vec,
    e2: Vec,
    de2: Vec,
    dde2: Vec,
    e3: Vec,
    de3: Vec,
    dde3: Vec,
    y: Vec,
    v: Vec,
    min_denominator: float = 1e-9,
) -> ExactTerms:
    """T(x), alpha, beta at position ``y`` (m) and velocity ``v`` (m/s), world ENU.

    ``sigma, d1..d3`` are the path and its lam-derivatives at the closest point ``lam*``;
    ``e2, e3`` the frame normals and their first and second lam-derivatives. ``eta1`` is the
    arclength at ``lam*``. ``D`` is floored at ``min_denominator * |sigma'|^2`` so that the result
    stays finite at (and beyond) the tube boundary; there it is no longer exact (the caller checks
    ``tube``).
    """
    rx = y[0] - sigma[0]
    ry = y[1] - sigma[1]
    rz = y[2] - sigma[2]
    vx, vy, vz = v
    ax, ay, az = d1
    bx, by, bz = d2
    cx, cy, cz = d3
    s2 = ax * ax + ay * ay + az * az
    s = math.sqrt(s2)
    d2r = bx * rx + by * ry + bz * rz
    den = s2 - d2r
    if den < min_denominator * s2:
        den = min_denominator * s2
    inv_den = 1.0 / den
    lam_dot = (ax * vx + ay * vy + az * vz) * inv_den
    d12 = ax * bx + ay * by + az * bz
    k = 3.0 * d12 - (cx * rx + cy * ry + cz * rz)
    d2v = bx * vx + by * vy + bz * vz
    ld2 = lam_dot * lam_dot
    # lam_ddot = c0 + <c1, a>,  c1 = sigma' / D
    c0 = (2.0 * d2v * lam_dot - k * ld2) * inv_den
    eta2 = s * lam_dot
    alpha1 = d12 / s * ld2 + s * c0
    sd = s * inv_den
    beta1 = (ax * sd, ay * sd, az * sd)

    def normal(e: Vec, de: Vec, dde: Vec) -> tuple[float, float, float, Vec]:
        ex, ey, ez = e
        px, py, pz = de
        der = px * rx + py * ry + pz * rz
        x1 = ex * rx + ey * ry + ez * rz
        x2 = lam_dot * der + ex * vx + ey * vy + ez * vz
        al = (
            c0 * der
            + ld2 * (dde[0] * rx + dde[1] * ry + dde[2] * rz)
            + 2.0 * lam_dot * (px * vx + py * vy + pz * vz)
            - ld2 * (px * ax + py * ay + pz * az)
        )
        w = der * inv_den
        return x1, x2, al, (ex + w * ax, ey + w * ay, ez + w * az)

    xi1, xi2, alpha2, beta2 = normal(e2, de2, dde2)
    phi1, phi2, alpha3, beta3 = normal(e3, de3, dde3)
    return ExactTerms(
        TransverseState(eta1, eta2, xi1, xi2, phi1, phi2),
        (alpha1, alpha2, alpha3),
        beta1,
        beta2,
        beta3,
        lam_dot,
        d2r / s2,
        (ax * rx + ay * ry + az * rz) / s,
    )


def inverse_columns(r1: Vec, r2: Vec, r3: Vec) -> tuple[Vec, Vec, Vec] | None:
    """Columns of the inverse of the 3x3 matrix with rows r1, r2, r3 (closed form), or None if singular."""
    c1 = (r2[1] * r3[2] - r2[2] * r3[1], r2[2] * r3[0] - r2[0] * r3[2], r2[0] * r3[1] - r2[1] * r3[0])
    det = r1[0] * c1[0] + r1[1] * c1[1] + r1[2] * c1[2]
    n1 = r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]
    n2 = r2[0] * r2[0] + r2[1] * r2[1] + r2[2] * r2[2]
    n3 = r3[0] * r3[0] + r3[1] * r3[1] + r3[2] * r3[2]
    if not abs(det) > 1e-12 * math.sqrt(n1 * n2 * n3):
        return None
    inv = 1.0 / det
    c2 = (r3[1] * r1[2] - r3[2] * r1[1], r3[2] * r1[0] - r3[0] * r1[2], r3[0] * r1[1] - r3[1] * r1[0])
    c3 = (r1[1] * r2[2] - r1[2] * r2[1], r1[2] * r2[0] - r1[0] * r2[2], r1[0] * r2[1] - r1[1] * r2[0])
    return (
        (c1[0] * inv, c1[1] * inv, c1[2] * inv),
        (c2[0] * inv, c2[1] * inv, c2[2] * inv),
        (c3[0] * inv, c3[1] * inv, c3[2] * inv),
    )
