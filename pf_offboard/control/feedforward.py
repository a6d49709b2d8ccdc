"""Attitude, thrust and body-rate feed-forward (Section IV-D), and the yaw specification psi(eta1).

Attitude: body z along ``f = a + g e_z`` (eq. 24), heading such that the ZYX yaw (the yaw of
eqs. 2-3) is psi. Body rates: ``omega_x, omega_y`` from eq. (25) with the jerk of the on-path
motion at the reference speed; ``omega_z`` from eqs. (2)-(3) given psi_dot. Checked against finite
differences of the commanded attitude in tests/control/test_feedforward.py.
"""

from __future__ import annotations

import math
from bisect import bisect_right

import numpy as np

from pf_offboard.control.types import YawSpec

Vec = tuple[float, float, float]
_TWO_PI = 2.0 * math.pi


def attitude_from_thrust(f: Vec, yaw_rad: float) -> tuple[Vec, Vec, Vec]:
    """Body axes (x_b, y_b, z_b) in world ENU: z_b = f/|f|, ZYX yaw = ``yaw_rad``.

    x_b is kept in the vertical plane of heading psi, so its horizontal projection points along
    (cos psi, sin psi). Requires f not horizontal (guaranteed by the tilt limit).
    """
    fx, fy, fz = f
    inv = 1.0 / math.sqrt(fx * fx + fy * fy + fz * fz)
    zx, zy, zz = fx * inv, fy * inv, fz * inv
    cy = math.cos(yaw_rad)
    sy = math.sin(yaw_rad)
    # x_b ∝ y_c × z_b with y_c = (-sin psi, cos psi, 0)
    xx = cy * zz
    xy = sy * zz
    xz = -sy * zy - cy * zx
    n = 1.0 / math.sqrt(xx * xx + xy * xy + xz * xz)
    xx *= n
    xy *= n
    xz *= n
    # y_b = z_b × x_b
    return (
        (xx, xy, xz),
        (zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx),
        (zx, zy, zz),
    )


def quaternion_from_axes(xb: Vec, yb: Vec, zb: Vec) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z), w >= 0, of the rotation with columns x_b, y_b, z_b (Shepperd)."""
    m00, m10, m20 = xb
    m01, m11, m21 = yb
    m02, m12, m22 = zb
    tr = m00 + m11 + m22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    if q[0] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] * n, q[1] * n, q[2] * n, q[3] * n)


def body_rates(axes: tuple[Vec, Vec, Vec], thrust: float, jerk: Vec, yaw_rate: float) -> Vec:
    """Body rates (FLU, rad/s) of the attitude of :func:`attitude_from_thrust` when f moves with
    ``df/dt = jerk`` (m/s^3) and psi with ``yaw_rate`` (rad/s).

    Eq. (25): ``h = (j - <z_b, j> z_b) / |f|``; ``omega_y = <x_b, h>``, ``omega_x = -<y_b, h>``.
    Eqs. (2)-(3) rows 2-3 with ``theta_dot`` eliminated:
    ``omega_z = (cos^2(theta) psi_dot - cos(theta) sin(phi) omega_y) / (cos(theta) cos(phi))``, where
    ``cos(theta) sin(phi) = y_b,z`` and ``cos(theta) cos(phi) = z_b,z`` and ``cos^2 theta = 1 - x_b,z^2``.
    """
    xb, yb, zb = axes
    jx, jy, jz = jerk
    jz_b = zb[0] * jx + zb[1] * jy + zb[2] * jz
    inv = 1.0 / thrust
    hx = (jx - jz_b * zb[0]) * inv
    hy = (jy - jz_b * zb[1]) * inv
    hz = (jz - jz_b * zb[2]) * inv
    wy = xb[0] * hx + xb[1] * hy + xb[2] * hz
    wx = -(yb[0] * hx + yb[1] * hy + yb[2] * hz)
    wz = ((1.0 - xb[2] * xb[2]) * yaw_rate - yb[2] * wy) / zb[2]
    return (wx, wy, wz)


def onpath_derivatives(d1: Vec, d2: Vec, d3: Vec) -> tuple[Vec, Vec, Vec]:
    """Unit tangent and arclength derivatives sigma_ss, sigma_sss from lambda-derivatives (chain rule).

    With ``s = |sigma'|``, ``s' = <sigma', sigma''>/s``, ``s'' = (|sigma''|^2 + <sigma', sigma'''>)/s - s'^2/s``:
    ``sigma_ss = sigma''/s^2 - sigma' s'/s^3``,
    ``sigma_sss = sigma'''/s^3 - 3 sigma'' s'/s^4 - sigma' s''/s^4 + 3 sigma' s'^2/s^5``.
    """
    ax, ay, az = d1
    bx, by, bz = d2
    cx, cy, cz = d3
    s2 = ax * ax + ay * ay + az * az
    s = math.sqrt(s2)
    inv = 1.0 / s
    sp = (ax * bx + ay * by + az * bz) * inv
    spp = (bx * bx + by * by + bz * bz + ax * cx + ay * cy + az * cz) * inv - sp * sp * inv
    i2 = inv * inv
    i3 = i2 * inv
    i4 = i3 * inv
    k1 = sp * i3
    t = (ax * inv, ay * inv, az * inv)
    ss = (bx * i2 - ax * k1, by * i2 - ay * k1, bz * i2 - az * k1)
    kb = 3.0 * sp * i4
    ka = -spp * i4 + 3.0 * sp * sp * i4 * inv
    sss = (cx * i3 - bx * kb + ax * ka, cy * i3 - by * kb + ay * ka, cz * i3 - bz * kb + az * ka)
    return t, ss, sss


class YawProfile:
    """psi(eta1) and d psi / d eta1 for a :class:`YawSpec` on a path (ENU yaw, radians)."""

    def __init__(self, spec: YawSpec, path_length_m: float, closed: bool, direction: float) -> None:
        self.spec = spec
        self.mode = spec.mode
        self.offset = float(spec.yaw_rad)
        self.direction = 1.0 if direction >= 0.0 else -1.0
        self.closed = closed
        self.length = float(path_length_m)
        if spec.mode == "table":
            self._build_table(spec.table_eta1_m_yaw_rad)

    def hold(self, yaw_rad: float) -> bool:
        """Hold ``yaw_rad`` from now on (``hold`` mode only; other modes keep their yaw): True if taken."""
        if self.mode != "hold" or not math.isfinite(yaw_rad):
            return False
        self.offset = math.remainder(float(yaw_rad), _TWO_PI)
        return True

    def _build_table(self, table: tuple[tuple[float, float], ...]) -> None:
        from scipy.interpolate import CubicSpline

        s = np.array([p[0] for p in table], dtype=float)
        psi = np.unwrap(np.array([p[1] for p in table], dtype=float))
        if self.closed:
            L = self.length
            if not (0.0 <= s[0] and s[-1] < s[0] + L):
                from pf_offboard.errors import InputError

                raise InputError("yaw.table", f"eta1 values must span less than one lap ({L:.3f} m) on a closed path")
            # Close the loop: the next lap starts at s0 + L with psi0 + 2 pi k, k chosen so that the
            # closing step is the short way round; a linear drift carries the 2 pi k, the rest is periodic.
            step = math.remainder(psi[0] - psi[-1], _TWO_PI)
            end = psi[-1] + step
            drift = (end - psi[0]) / L
            s_ext = np.append(s, s[0] + L)
            psi_ext = np.append(psi, end) - drift * (s_ext - s[0])
            psi_ext[-1] = psi_ext[0]
            spl = CubicSpline(s_ext, psi_ext, bc_type="periodic")
            self._drift = drift
        else:
            spl = CubicSpline(s, psi, bc_type="natural")
            self._drift = 0.0
        self._s0 = float(s[0])
        self._knots = spl.x.tolist()
        self._coef = [tuple(spl.c[:, i].tolist()) for i in range(spl.c.shape[1])]
        self._nseg = len(self._coef)
        self._s_last = float(spl.x[-1])
        # Beyond an open table's ends: continue linearly with the end slope. The natural spline has
        # zero second derivative at its ends, so this extension keeps psi C2.
        self._ends = (
            (float(s[0]), float(spl(s[0])), float(spl(s[0], 1))),
            (float(s[-1]), float(spl(s[-1])), float(spl(s[-1], 1))),
        )

    def _table(self, eta1: float) -> tuple[float, float]:
        x = eta1
        if self.closed:
            x = self._s0 + (eta1 - self._s0) % self.length
        elif x <= self._knots[0] or x >= self._s_last:
            x0, p0, d0 = self._ends[0] if x <= self._knots[0] else self._ends[1]
            return p0 + d0 * (x - x0), d0
        i = bisect_right(self._knots, x) - 1
        if i < 0:
            i = 0
        elif i >= self._nseg:
            i = self._nseg - 1
        c3, c2, c1, c0 = self._coef[i]
        u = x - self._knots[i]
        psi = c0 + u * (c1 + u * (c2 + u * c3))
        dpsi = c1 + u * (2.0 * c2 + 3.0 * u * c3)
        return psi + self._drift * (x - self._s0), dpsi + self._drift

    def evaluate(self, eta1: float, tangent: Vec, sigma_ss: Vec) -> tuple[float, float]:
        """(psi rad, d psi / d eta1 rad/m) at arclength ``eta1``; ``tangent``, ``sigma_ss`` there."""
        if self.mode == "constant" or self.mode == "hold":
            return self.offset, 0.0
        if self.mode == "tangent":
            hx = self.direction * tangent[0]
            hy = self.direction * tangent[1]
            n2 = hx * hx + hy * hy
            psi = math.atan2(hy, hx) + self.offset
            if n2 < 1e-6:
                # vertical tangent: heading undefined; no rate feed-forward
                return psi, 0.0
            return psi, (tangent[0] * sigma_ss[1] - tangent[1] * sigma_ss[0]) / n2
        return self._table(eta1)
