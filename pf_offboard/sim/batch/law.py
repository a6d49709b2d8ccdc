"""Exact transverse terms, the feasible thrust set and the control law for N states at once.

Mirrors :func:`pf_offboard.control.transverse.exact_terms` / ``inverse_columns``,
:class:`pf_offboard.control.feasible.ThrustSet` and :class:`pf_offboard.control.law.ControlLaw`
function by function (same names, same operations in the same order); a branch of the scalar code
is a mask here. The law's constants come from the scalar :class:`ControlLaw` itself, so a change
of its gains, limits or derived constants reaches both engines.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from pf_offboard.control.feasible import ThrustSet
from pf_offboard.control.law import BISECTION_STEPS, BRAKING_RESERVE_MARGIN_M_S, BRAKING_RESERVE_SHARE, ControlLaw
from pf_offboard.control.types import GRAVITY_M_S2, Gains, Limits
from pf_offboard.sim.batch.geometry import hypot, power

Arr = NDArray[np.float64]
Mask = NDArray[np.bool_]
V = tuple[Arr, Arr, Arr]
G = GRAVITY_M_S2
_INF = math.inf


def _where3(m: Mask, a: V, b: V) -> V:
    return (np.where(m, a[0], b[0]), np.where(m, a[1], b[1]), np.where(m, a[2], b[2]))


# ---------------------------------------------------------------------------------- transverse
class Terms(NamedTuple):
    """:class:`pf_offboard.control.transverse.ExactTerms` for N states (state as six arrays)."""

    eta1: Arr
    eta2: Arr
    xi1: Arr
    xi2: Arr
    phi1: Arr
    phi2: Arr
    alpha: V
    beta1: V
    beta2: V
    beta3: V
    lam_dot: Arr
    tube: Arr
    tangential_offset_m: Arr


def exact_terms(eta1: Arr, sigma: V, d1: V, d2: V, d3: V, e2: V, de2: V, dde2: V, e3: V, de3: V, dde3: V,
                y: V, v: V, min_denominator: float = 1e-9) -> Terms:  # fmt: skip
    """:func:`pf_offboard.control.transverse.exact_terms`."""
    rx = y[0] - sigma[0]
    ry = y[1] - sigma[1]
    rz = y[2] - sigma[2]
    vx, vy, vz = v
    ax, ay, az = d1
    bx, by, bz = d2
    cx, cy, cz = d3
    s2 = ax * ax + ay * ay + az * az
    s = np.sqrt(s2)
    d2r = bx * rx + by * ry + bz * rz
    den = s2 - d2r
    floor = min_denominator * s2
    den = np.where(den < floor, floor, den)
    inv_den = 1.0 / den
    lam_dot = (ax * vx + ay * vy + az * vz) * inv_den
    d12 = ax * bx + ay * by + az * bz
    k = 3.0 * d12 - (cx * rx + cy * ry + cz * rz)
    d2v = bx * vx + by * vy + bz * vz
    ld2 = lam_dot * lam_dot
    c0 = (2.0 * d2v * lam_dot - k * ld2) * inv_den
    eta2 = s * lam_dot
    alpha1 = d12 / s * ld2 + s * c0
    sd = s * inv_den
    beta1 = (ax * sd, ay * sd, az * sd)

    def normal(e: V, de: V, dde: V) -> tuple[Arr, Arr, Arr, V]:
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
    return Terms(eta1, eta2, xi1, xi2, phi1, phi2, (alpha1, alpha2, alpha3), beta1, beta2, beta3, lam_dot, d2r / s2,
                 (ax * rx + ay * ry + az * rz) / s)  # fmt: skip


def inverse_columns(r1: V, r2: V, r3: V) -> tuple[tuple[V, V, V], Mask]:
    """:func:`pf_offboard.control.transverse.inverse_columns`: the columns, and which rows are
    regular (the scalar's None is ``~ok``; those rows hold garbage)."""
    c1 = (r2[1] * r3[2] - r2[2] * r3[1], r2[2] * r3[0] - r2[0] * r3[2], r2[0] * r3[1] - r2[1] * r3[0])
    det = r1[0] * c1[0] + r1[1] * c1[1] + r1[2] * c1[2]
    n1 = r1[0] * r1[0] + r1[1] * r1[1] + r1[2] * r1[2]
    n2 = r2[0] * r2[0] + r2[1] * r2[1] + r2[2] * r2[2]
    n3 = r3[0] * r3[0] + r3[1] * r3[1] + r3[2] * r3[2]
    ok = np.abs(det) > 1e-12 * np.sqrt(n1 * n2 * n3)
    inv = 1.0 / np.where(ok, det, 1.0)
    c2 = (r3[1] * r1[2] - r3[2] * r1[1], r3[2] * r1[0] - r3[0] * r1[2], r3[0] * r1[1] - r3[1] * r1[0])
    c3 = (r1[1] * r2[2] - r1[2] * r2[1], r1[2] * r2[0] - r1[0] * r2[2], r1[0] * r2[1] - r1[1] * r2[0])
    return (
        (c1[0] * inv, c1[1] * inv, c1[2] * inv),
        (c2[0] * inv, c2[1] * inv, c2[2] * inv),
        (c3[0] * inv, c3[1] * inv, c3[2] * inv),
    ), ok


# ---------------------------------------------------------------------------------- thrust set
class BatchThrustSet:
    """:class:`pf_offboard.control.feasible.ThrustSet` on arrays."""

    def __init__(self, ts: object) -> None:
        self.min_thrust_m_s2 = float(ts.min_thrust_m_s2)  # type: ignore[attr-defined]
        self.max_thrust_m_s2 = float(ts.max_thrust_m_s2)  # type: ignore[attr-defined]
        self.tan_tilt = float(ts.tan_tilt)  # type: ignore[attr-defined]
        self._ts = ThrustSet(self.min_thrust_m_s2, self.max_thrust_m_s2, self.tan_tilt)

    def active(self, f: V, rel: float = 1e-6) -> tuple[Mask, Mask]:
        fx, fy, fz = f
        tol = rel * self.max_thrust_m_s2
        tilt = hypot(fx, fy) >= self.tan_tilt * fz - tol
        thrust = (fz <= self.min_thrust_m_s2 + tol) | (np.sqrt(fx * fx + fy * fy + fz * fz) >= self.max_thrust_m_s2 - tol)
        return tilt, thrust

    def line_interval(self, f0: V, m: V) -> tuple[Arr, Arr, Mask]:
        """``(lo, hi, empty)``: the scalar's None is ``empty`` (:meth:`ThrustSet.line_intervals`,
        the scalar's operations elementwise)."""
        return self._ts.line_intervals(f0, m)

    def clip(self, f: V) -> V:
        fx, fy, fz = f
        tmin, tmax = self.min_thrust_m_s2, self.max_thrust_m_s2
        bad = ~(np.isfinite(fx) & np.isfinite(fy) & np.isfinite(fz))
        fz = np.where(fz < tmin, tmin, fz)
        h = hypot(fx, fy)
        hmax = self.tan_tilt * fz
        over = h > hmax
        k = np.where(over, hmax / np.where(over, h, 1.0), 1.0)
        fx = np.where(over, fx * k, fx)
        fy = np.where(over, fy * k, fy)
        n = np.sqrt(fx * fx + fy * fy + fz * fz)
        big = n > tmax
        k = np.where(big, tmax / np.where(big, n, 1.0), 1.0)
        fx = np.where(big, fx * k, fx)
        fy = np.where(big, fy * k, fy)
        fz = np.where(big, fz * k, fz)
        low = big & (fz < tmin)
        if low.any():  # only if T_max cos(tilt) < T_min (rejected by Limits)
            fz = np.where(low, tmin, fz)
            h = np.sqrt(np.maximum(tmax**2 - fz * fz, 0.0))
            hh = hypot(fx, fy)
            sh = low & (hh > h)
            fx = np.where(sh, fx * (h / np.where(sh, hh, 1.0)), fx)
            fy = np.where(sh, fy * (h / np.where(sh, hh, 1.0)), fy)
        hov = max(tmin, min(9.81, tmax))
        return (np.where(bad, 0.0, fx), np.where(bad, 0.0, fy), np.where(bad, hov, fz))


# ---------------------------------------------------------------------------------- the law
BISECT_BITS = 4  # bits of the allocation's bisection decided per pass (2^4 - 1 candidates at once)


def _bisect(ts: BatchThrustSet, coast: Mask, b: V, t: V, m1: V, steps: int) -> Arr:
    """The scalar allocation's bisection (``lo`` after ``steps`` halvings of [0, 1]) for every row.

    The scalar law halves sequentially; here BISECT_BITS bits are decided per pass by testing all
    the dyadic points of the pass at once. Feasibility along the scaling is an interval containing
    0 (the thrust set is convex), so the largest feasible point of each pass is the one the
    sequential halving reaches: the same dyadic ``lo``, computed from the same products."""
    n = len(coast)
    lo = np.zeros(n)
    done = 0
    while done < steps:
        bits = min(BISECT_BITS, steps - done)
        k = (1 << bits) - 1
        h = 0.5 ** (done + bits)  # the spacing of this pass's points (exact: a power of two)
        j = np.arange(1, k + 1, dtype=float)
        mid = (lo[:, None] + j[None, :] * h).ravel()  # (n * k,) row-major: row r's points together
        rep = lambda a: np.repeat(a, k)  # noqa: E731
        c = rep(coast)
        bx, by, bz = rep(b[0]), rep(b[1]), rep(b[2])
        f = _where3(c, (mid * bx, mid * by, mid * bz + G),
                    (bx + mid * rep(t[0]), by + mid * rep(t[1]), bz + mid * rep(t[2]) + G))  # fmt: skip
        ok = ~ts.line_interval(f, (rep(m1[0]), rep(m1[1]), rep(m1[2])))[2]
        ok = ok.reshape(n, k)
        # the sequential halving moves lo up to the largest feasible point it visits: with a monotone
        # predicate, the number of feasible points of the pass from its start
        first_bad = np.where(ok.all(axis=1), k, np.argmin(ok, axis=1))
        lo = lo + first_bad * h
        done += bits
    return lo


class LawOut(NamedTuple):
    """:class:`pf_offboard.control.law.LawOutput` for N states."""

    accel: V
    tangential: Mask
    transversal: Mask
    approach_speed: Mask


class BatchLaw:
    """:class:`pf_offboard.control.law.ControlLaw` on arrays; its constants are the scalar law's.

    ``per_flight``: one scalar law per row (a gain sweep: the gains differ, the limits do not);
    the gain-dependent constants are then arrays."""

    def __init__(self, gains: Gains, limits: Limits, per_flight: list[ControlLaw] | None = None) -> None:
        self.scalar = law = ControlLaw(gains, limits)
        self.thrust_set = BatchThrustSet(law.thrust_set)
        self.u_max, self.a_dec, self.v_app = law.u_max, law.a_dec, law.v_app
        self.jerk = law.jerk
        # The speed loop's bound: a constant of the law (limits.max_tangential_accel_m_s2), or a
        # cap the caller passes per step (the follower's start ramp) where the scalar law takes one.
        self.cap_per_call = not hasattr(law, "u_t_max")
        self.u_t_max = math.inf if self.cap_per_call else law.u_t_max
        names = ("kp", "kd", "k_pos", "kd_t", "k_pos_t", "dv_lin", "dv_lin_t", "c_cbrt")
        if per_flight is None:
            for name in names:
                setattr(self, name, getattr(law, name))
        else:
            for other in per_flight:
                for name in ("u_max", "a_dec", "v_app", "jerk"):
                    if getattr(other, name) != getattr(law, name):
                        raise ValueError(f"BatchLaw: per-flight laws must share their limits ({name} differs)")
            for name in names:
                setattr(self, name, np.array([getattr(other, name) for other in per_flight], dtype=float))

    def shape(self, k: float, dv_lin: float, dv: Arr) -> Arr:
        return np.where(dv <= dv_lin, k * dv, np.sqrt(2.0 * self.jerk * np.maximum(dv - 0.5 * dv_lin, 0.0)))

    def approach_speed(self, dist_m: Arr) -> tuple[Arr, Mask]:
        lin = self.k_pos * dist_m
        brake = np.sqrt(2.0 * self.a_dec * dist_m)
        v = np.where(lin < brake, lin, brake)
        if np.any(np.asarray(self.c_cbrt) < _INF):
            jerk = self.c_cbrt * power(dist_m, 2.0 / 3.0)
            v = np.where((jerk < v) & (np.asarray(self.c_cbrt) < _INF), jerk, v)
        limited = self.v_app < v
        return np.where(limited, self.v_app, v), limited

    def stopping_speed(self, dist_m: Arr) -> Arr:
        pos = dist_m > 0.0
        d = np.where(pos, dist_m, 0.0)
        lin = self.k_pos_t * d
        brake = np.sqrt(2.0 * self.a_dec * d)
        return np.where(pos, np.where(lin < brake, lin, brake), 0.0)

    def transversal(self, xi1: Arr, xi2: Arr, phi1: Arr, phi2: Arr) -> tuple[Arr, Arr, Mask, Mask]:
        d = hypot(xi1, phi1)
        pos = d > 0.0
        speed, limited = self.approach_speed(d)
        k = speed / np.where(pos, d, 1.0)
        vx = np.where(pos, -k * xi1, 0.0)
        vy = np.where(pos, -k * phi1, 0.0)
        limited = limited & pos
        ex, ey = vx - xi2, vy - phi2
        dv = hypot(ex, ey)
        linear = dv <= self.dv_lin
        n_sh = self.shape(self.kd, self.dv_lin, dv)
        r = n_sh / np.where(linear, 1.0, dv)
        ux = np.where(linear, self.kd * ex, ex * r)
        uy = np.where(linear, self.kd * ey, ey * r)
        n = np.where(linear, self.kd * dv, n_sh)
        red = n > self.u_max
        k = self.u_max / np.where(red, n, 1.0)
        return np.where(red, ux * k, ux), np.where(red, uy * k, uy), red, limited

    def tangential(self, eta2_ref: Arr, eta2: Arr, cap: Arr | float | None = None) -> Arr:
        dv = eta2_ref - eta2
        adv = np.abs(dv)
        u = np.where(adv <= self.dv_lin_t, self.kd_t * dv, np.copysign(self.shape(self.kd_t, self.dv_lin_t, adv), dv))
        cap = self.u_t_max if cap is None else cap
        return np.where(u > cap, cap, np.where(u < -cap, -cap, u))

    def tube(self, terms: Terms, eta2_ref: Arr, feedforward_m_s2: Arr | None = None,
             bisection_steps: int = BISECTION_STEPS, tangential_cap: Arr | None = None) -> tuple[LawOut, Mask]:  # fmt: skip
        """``ControlLaw.tube``: the output and which rows have one (the scalar's None: ``~ok``)."""
        (m1, m2, m3), ok = inverse_columns(terms.beta1, terms.beta2, terms.beta3)
        al1, al2, al3 = terms.alpha
        u_xi, u_phi, reduced, limited = self.transversal(terms.xi1, terms.xi2, terms.phi1, terms.phi2)
        cap = self.u_t_max if tangential_cap is None else tangential_cap
        u_eta = self.tangential(eta2_ref, terms.eta2, cap)
        bounded = np.abs(u_eta) >= cap
        if feedforward_m_s2 is not None:
            u_eta = np.where(feedforward_m_s2 != 0.0, u_eta + feedforward_m_s2, u_eta)
        bx = -(m1[0] * al1 + m2[0] * al2 + m3[0] * al3)
        by = -(m1[1] * al1 + m2[1] * al2 + m3[1] * al3)
        bz = -(m1[2] * al1 + m2[2] * al2 + m3[2] * al3)
        tx = m2[0] * u_xi + m3[0] * u_phi
        ty = m2[1] * u_xi + m3[1] * u_phi
        tz = m2[2] * u_xi + m3[2] * u_phi
        ts = self.thrust_set
        mu = np.ones_like(bx)
        lo_iv, hi_iv, empty = ts.line_interval((bx + tx, by + ty, bz + tz + G), m1)
        empty &= ok
        fallback = np.zeros_like(empty)
        fb_f: V | None = None
        if empty.any():
            idx = np.flatnonzero(empty)
            reduced = reduced.copy()
            reduced[idx] = True
            b_ = (bx[idx], by[idx], bz[idx])
            t_ = (tx[idx], ty[idx], tz[idx])
            n1 = (m1[0][idx], m1[1][idx], m1[2][idx])
            coast = ts.line_interval((b_[0], b_[1], b_[2] + G), n1)[2]
            lo = _bisect(ts, coast, b_, t_, n1, bisection_steps)
            bxi = np.where(coast, lo * b_[0], b_[0])
            byi = np.where(coast, lo * b_[1], b_[1])
            bzi = np.where(coast, lo * b_[2], b_[2])
            mui = np.where(coast, 0.0, lo)
            e2, e2r = terms.eta2[idx], np.broadcast_to(eta2_ref, terms.eta2.shape)[idx]
            over = np.abs(e2) - np.abs(e2r) - BRAKING_RESERVE_MARGIN_M_S  # the scalar law's gated braking reserve
            share = BRAKING_RESERVE_SHARE * np.minimum(np.maximum(over, 0.0) / BRAKING_RESERVE_MARGIN_M_S, 1.0)
            brake = ~coast & (u_eta[idx] * e2 < 0.0) & (share > 0.0)
            if brake.any():
                want = share[brake] * u_eta[idx][brake]
                lo_b, hi_b = np.zeros(int(brake.sum())), mui[brake].copy()
                tb = (t_[0][brake], t_[1][brake], t_[2][brake])
                bb = (b_[0][brake], b_[1][brake], b_[2][brake])
                nb = (n1[0][brake], n1[1][brake], n1[2][brake])
                for _ in range(bisection_steps):
                    mid = 0.5 * (lo_b + hi_b)
                    lm, hm, em = ts.line_interval((bb[0] + mid * tb[0], bb[1] + mid * tb[1], bb[2] + mid * tb[2] + G), nb)
                    bad = em | np.where(want < 0.0, lm > want, hm < want)
                    hi_b = np.where(bad, mid, hi_b)
                    lo_b = np.where(bad, lo_b, mid)
                mui = mui.copy()
                mui[brake] = lo_b
            bx, by, bz, mu = bx.copy(), by.copy(), bz.copy(), mu.copy()
            bx[idx], by[idx], bz[idx], mu[idx] = bxi, byi, bzi, mui
            f0 = (bxi + mui * t_[0], byi + mui * t_[1], bzi + mui * t_[2] + G)
            lo2, hi2, e2 = ts.line_interval(f0, n1)
            lo_iv, hi_iv = lo_iv.copy(), hi_iv.copy()
            lo_iv[idx], hi_iv[idx] = lo2, hi2
            if e2.any():  # only through rounding at the bisection's end: the clip
                fallback = np.zeros_like(empty)
                fallback[idx[e2]] = True
                fb_f = ts.clip(f0)
                fb_idx = idx
        below = u_eta < lo_iv
        above = ~below & (u_eta > hi_iv)
        u_eta = np.where(below, lo_iv, np.where(above, hi_iv, u_eta))
        clipped = below | above
        a = (bx + mu * tx + m1[0] * u_eta, by + mu * ty + m1[1] * u_eta, bz + mu * tz + m1[2] * u_eta)
        tang = clipped | bounded
        trans = reduced
        if fb_f is not None:
            full = [np.zeros_like(bx) for _ in range(3)]
            for k in range(3):
                full[k][fb_idx] = fb_f[k]
            full[2] = full[2] - G
            a = _where3(fallback, (full[0], full[1], full[2]), a)
            tang = tang | fallback
            trans = trans | fallback
        return LawOut(a, tang, trans, limited), ok

    def approach(self, r: V, v: V, t: V, eta2_ref: Arr, tangential_cap: Arr | None = None) -> LawOut:
        d = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        pos = d > 0.0
        speed, limited = self.approach_speed(d)
        k = np.where(pos, speed / np.where(pos, d, 1.0), 0.0)
        limited = limited & pos
        ex = -k * r[0] - v[0]
        ey = -k * r[1] - v[1]
        ez = -k * r[2] - v[2]
        et = ex * t[0] + ey * t[1] + ez * t[2]
        px, py, pz = ex - et * t[0], ey - et * t[1], ez - et * t[2]
        dv = np.sqrt(px * px + py * py + pz * pz)
        n = self.shape(self.kd, self.dv_lin, dv)
        nz = dv > 0.0
        c = n / np.where(nz, dv, 1.0)
        px, py, pz = np.where(nz, px * c, px), np.where(nz, py * c, py), np.where(nz, pz * c, pz)
        reduced = n > self.u_max
        c = self.u_max / np.where(reduced, n, 1.0)
        px, py, pz = np.where(reduced, px * c, px), np.where(reduced, py * c, py), np.where(reduced, pz * c, pz)
        n = np.where(reduced, self.u_max, n)
        cap = self.u_t_max if tangential_cap is None else tangential_cap
        at = self.tangential(eta2_ref, -et, cap)
        room = np.sqrt(np.maximum(self.u_max * self.u_max - n * n, 0.0))
        clipped = np.abs(at) >= cap
        hi = at > room
        lo = ~hi & (at < -room)
        at = np.where(hi, room, np.where(lo, -room, at))
        clipped = clipped | hi | lo
        f = self.thrust_set.clip((px + at * t[0], py + at * t[1], pz + at * t[2] + G))
        return LawOut((f[0], f[1], f[2] - G), clipped, reduced, limited)
