"""The path follower for N flights at once (mirrors :class:`pf_offboard.control.PathFollower`,
its speed profile, yaw profile, feed-forward and inner-loop compensator, function by function).

Built from a scalar :class:`~pf_offboard.control.PathFollower` (the same Gains / Limits / Config
objects), whose constants it reads, so a change of the scalar controller's defaults reaches both
engines; a change of its *code* needs the mirrored edit here (the equality tests catch drift).
The compensator's clock is shared by the batch (every flight is sampled at the same instants,
as in a lockstep sweep).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pf_offboard.control import follower as F
from pf_offboard.control.compensator import (
    GUARD_MARGIN_M,
    GUARD_RATIO,
    GUARD_REFERENCE_TIME_S,
    GUARD_SLEW_FACTOR,
    GUARD_SLEW_S,
    GUARD_TIME_S,
    GUARD_WATCH_S,
    ADAPT_DRAG_SLEW,
    DRAG_FOLLOW_S,
    ADAPT_GAIN_SLEW,
    ADAPT_SLEW,
    ADOPT_VERTICAL,
    MAX_DRAG_FEEDBACK_M_S2,
    MAX_GAP_S,
    OVERSPEED_MARGIN_M_S,
    OFFSET_INTEGRAL_BAND_M,
    vertical_lag,
)
from pf_offboard.control.profile import REPLAN_BLEND_S
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.sim.batch.adaptive import BatchIdentifier
from pf_offboard.sim.batch.geometry import BatchPath, atan2, power
from pf_offboard.sim.batch.law import BatchLaw, LawOut, Terms, _where3, exact_terms
from pf_offboard.sim.batch.projection import BatchProjector

Arr = NDArray[np.float64]
Mask = NDArray[np.bool_]
V = tuple[Arr, Arr, Arr]
G = GRAVITY_M_S2


class BatchCommand(NamedTuple):
    """:class:`pf_offboard.control.types.Command` for N flights (arrays with a leading axis of N
    for vectors: acceleration (N, 3), attitude (N, 4), body_rates (N, 3))."""

    acceleration: Arr
    thrust: Arr
    attitude: Arr
    body_rates: Arr
    yaw: Arr
    yaw_rate: Arr
    eta1: Arr
    eta2: Arr
    xi1: Arr
    xi2: Arr
    phi1: Arr
    phi2: Arr
    lam: Arr
    cross_track_m: Arr
    sat_tangential: Mask
    sat_transversal: Mask
    sat_tilt: Mask
    sat_thrust: Mask
    sat_approach_speed: Mask
    eta2_ref_m_s: Arr
    finite: Mask  # False: the scalar follower would have raised (no finite command)


def _approach_weight(tube: Arr, dist_m: Arr) -> Arr:
    return np.maximum((tube - F.TUBE_INNER) / (F.TUBE_OUTER - F.TUBE_INNER), (dist_m - F.FAR_INNER_M) / (F.FAR_OUTER_M - F.FAR_INNER_M))


def _blended_speed(eta2: Arr, w: Arr, tan: V, v: V) -> Arr:
    v_t = tan[0] * v[0] + tan[1] * v[1] + tan[2] * v[2]
    return np.where(w <= 0.0, eta2, np.where(w >= 1.0, v_t, (1.0 - w) * eta2 + w * v_t))


def onpath_derivatives(d1: V, d2: V, d3: V) -> tuple[V, V, V]:
    """:func:`pf_offboard.control.feedforward.onpath_derivatives`."""
    ax, ay, az = d1
    bx, by, bz = d2
    cx, cy, cz = d3
    s2 = ax * ax + ay * ay + az * az
    s = np.sqrt(s2)
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


def attitude_from_thrust(f: V, yaw_rad: Arr) -> tuple[V, V, V]:
    """:func:`pf_offboard.control.feedforward.attitude_from_thrust`."""
    fx, fy, fz = f
    inv = 1.0 / np.sqrt(fx * fx + fy * fy + fz * fz)
    zx, zy, zz = fx * inv, fy * inv, fz * inv
    cy = np.cos(yaw_rad)
    sy = np.sin(yaw_rad)
    xx = cy * zz
    xy = sy * zz
    xz = -sy * zy - cy * zx
    n = 1.0 / np.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx * n, xy * n, xz * n
    return (xx, xy, xz), (zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx), (zx, zy, zz)


def quaternion_from_axes(xb: V, yb: V, zb: V) -> tuple[Arr, Arr, Arr, Arr]:
    """:func:`pf_offboard.control.feedforward.quaternion_from_axes` (Shepperd's branches as masks)."""
    m00, m10, m20 = xb
    m01, m11, m21 = yb
    m02, m12, m22 = zb
    tr = m00 + m11 + m22
    b0 = tr > 0.0
    b1 = ~b0 & (m00 > m11) & (m00 > m22)
    b2 = ~b0 & ~b1 & (m11 > m22)
    arg = np.where(b0, tr + 1.0, np.where(b1, 1.0 + m00 - m11 - m22, np.where(b2, 1.0 + m11 - m00 - m22, 1.0 + m22 - m00 - m11)))
    s = 2.0 * np.sqrt(np.maximum(arg, 0.0))
    s = np.where(s == 0.0, 1.0, s)
    q0 = np.where(b0, 0.25 * s, np.where(b1, (m21 - m12) / s, np.where(b2, (m02 - m20) / s, (m10 - m01) / s)))
    q1 = np.where(b0, (m21 - m12) / s, np.where(b1, 0.25 * s, np.where(b2, (m01 + m10) / s, (m02 + m20) / s)))
    q2 = np.where(b0, (m02 - m20) / s, np.where(b1, (m01 + m10) / s, np.where(b2, 0.25 * s, (m12 + m21) / s)))
    q3 = np.where(b0, (m10 - m01) / s, np.where(b1, (m02 + m20) / s, np.where(b2, (m12 + m21) / s, 0.25 * s)))
    neg = q0 < 0.0
    q0, q1, q2, q3 = np.where(neg, -q0, q0), np.where(neg, -q1, q1), np.where(neg, -q2, q2), np.where(neg, -q3, q3)
    n = 1.0 / np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 * n, q1 * n, q2 * n, q3 * n


def body_rates(axes: tuple[V, V, V], thrust: Arr, jerk: V, yaw_rate: Arr) -> V:
    """:func:`pf_offboard.control.feedforward.body_rates`."""
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
    return wx, wy, wz


class _Profile:
    """:meth:`pf_offboard.control.profile.SpeedProfile.evaluate` on arrays."""

    def __init__(self, p: Any) -> None:
        self.p = p
        self.c = np.array(p._c, dtype=float)

    def evaluate(self, eta1: Arr) -> tuple[Arr, Arr, Arr]:
        p = self.p
        L, ds, n, c = p.length_m, p._ds, p._n, self.c
        x = np.mod(eta1, L) if p.closed else np.where(eta1 < 0.0, 0.0, np.where(eta1 > L, L, eta1))
        u = x / ds
        i = np.floor(u + 0.5).astype(np.int64)
        tau = u - i
        if p.closed:
            cm, c0, cp = c[(i - 1) % n], c[i % n], c[(i + 1) % n]
        else:
            i = np.where(i > n - 1, n - 1, i)
            c0 = c[i]
            cm = np.where(i > 0, c[np.maximum(i - 1, 0)], 2.0 * c[0] - c[1])
            cp = np.where(i < n - 1, c[np.minimum(i + 1, n - 1)], 2.0 * c[n - 1] - c[n - 2])
        lo, hi = 0.5 - tau, 0.5 + tau
        b = 0.5 * cm * lo * lo + c0 * (0.75 - tau * tau) + 0.5 * cp * hi * hi
        zero = b <= 1e-12
        db = (cp * hi - cm * lo - 2.0 * tau * c0) / ds
        ddb = (cm - 2.0 * c0 + cp) / (ds * ds)
        v = np.sqrt(np.where(zero, 1.0, b))
        dv = 0.5 * db / v
        ddv = (0.5 * ddb - dv * dv) / v
        s = p.direction
        return np.where(zero, 0.0, s * v), np.where(zero, 0.0, s * dv), np.where(zero, 0.0, s * ddv)


class _Compensator:
    """:class:`pf_offboard.control.compensator.InnerLoopCompensator` for N flights sampled at the
    same instants (the recorded setpoints share their times; their values are per flight)."""

    def __init__(self, c: Any, n: int) -> None:
        self.c = c
        self.n = n
        self.horizon_s, self.hold_s, self.lag, self.gain, self.drag = c.horizon_s, c.hold_s, c.lag, c.gain, c.drag
        self.observer_rad_s, self.max_disturbance_m_s2 = c.observer_rad_s, c.max_disturbance_m_s2
        self._history_s = c._history_s
        # in-flight identification (the scalar's identifier): the lag, the dead time (the horizon)
        # and the drag become per flight, the adopted model too (NaN: none, the scalar's None)
        self.identifier = BatchIdentifier(c.identifier, n) if c.identifier is not None else None
        if self.identifier is not None:
            if c.holds:  # the identifier runs with the typical model only, whose groups share a delay
                raise NotImplementedError("the batch engine identifies with equal horizontal and vertical delays only")
            full = lambda x: np.full(n, float(x))  # noqa: E731
            self.horizon_s = full(c.horizon_s)
            self.lag = (full(c.lag[0]), full(c.lag[1]), full(c.lag[2]))
            self.drag = (full(c.drag[0]), full(c.drag[1]), full(c.drag[2]))
            self.gain = (full(c.gain[0]), full(c.gain[1]), full(c.gain[2]))
            target = c._target if c._target is not None else (math.nan, math.nan)
            self._target = (full(target[0]), full(target[1]))
            self._drag_f = full(math.nan if c._drag_followed is None else c._drag_followed)  # the scalar's _drag_followed
            m = c.identified
            known = (math.nan,) * 7 if m is None else (m.lag_s, m.delay_s, m.drag_1_s, m.adopted_at_s, m.gain_xy, m.gain_z, m.drag_z_1_s)
            self._identified = tuple(full(x) for x in known)  # what was adopted last, per flight
            # the rollback guard (InnerLoopCompensator.watch), per flight: the watch after an
            # adoption (its start, the reference RMS, the model flown before, the candidates), the
            # initial model restored, the last rollback
            nan, z = full(math.nan), np.zeros(n, dtype=bool)
            if c._watch is not None or c._restore is not None or c.rolled_back is not None:
                raise NotImplementedError("the batch engine starts from a compensator the guard has not acted on")
            self._w_on, self._w_t0, self._w_ref_c, self._w_ref_s = z, nan, nan, nan
            self._w_before: tuple[Arr, ...] = (nan,) * 8  # lag, delay, gain x/y/z, drag x/y/z
            self._w_ident = tuple(full(x) for x in known)
            self._w_prev = self._w_cand = np.full(n, -1, dtype=np.int64)
            self._w_target = (nan, nan)
            self._restoring = z
            self._r: tuple[Arr, ...] = (nan,) * 8
            self._rollback_until = full(-math.inf)
            self._rb: tuple[Arr, ...] = (nan,) * 8  # at_s, rejected delay/gain/drag/adopted_at, cross, reference, speed
        self.reset()

    def reset(self) -> None:
        z = np.zeros(self.n)
        self._t: float | None = None
        self._v_hat = (z, z, z)
        self._a_f = (z, z, z)
        self.disturbance = (z, z, z)
        self._sent: list[tuple[float, V]] = []
        self._t_int: float | None = None
        self.speed_offset_m_s = z
        self.xi1_offset_m = z
        self.phi1_offset_m = z
        if self.identifier is not None:
            self.identifier.reset()
            self._err_t: float | None = None
            self._cross_ms, self._speed_ms, self._slow_cross_ms, self._slow_speed_ms = z, z, z, z
            self._w_on = np.zeros(self.n, dtype=bool)

    def integral_offsets(self) -> tuple[Arr, Arr, Arr]:
        return self.speed_offset_m_s, self.xi1_offset_m, self.phi1_offset_m

    def integrate(self, time_s: float, speed_error: Arr, xi1: Arr, phi1: Arr, free: Mask) -> None:
        c = self.c
        t_prev, self._t_int = self._t_int, time_s
        if t_prev is None or not (0.0 < time_s - t_prev <= MAX_GAP_S):
            return
        dt = time_s - t_prev
        ks, kx = c.speed_integral_rad_s * dt, c.offset_integral_rad_s * dt
        vmax, pmax = c.max_speed_offset_m_s, c.max_position_offset_m
        self.speed_offset_m_s = np.where(free, np.minimum(vmax, np.maximum(-vmax, self.speed_offset_m_s + ks * speed_error)), self.speed_offset_m_s)
        near = free & (xi1 * xi1 + phi1 * phi1 <= OFFSET_INTEGRAL_BAND_M * OFFSET_INTEGRAL_BAND_M)
        self.xi1_offset_m = np.where(near, np.minimum(pmax, np.maximum(-pmax, self.xi1_offset_m + kx * xi1)), self.xi1_offset_m)
        self.phi1_offset_m = np.where(near, np.minimum(pmax, np.maximum(-pmax, self.phi1_offset_m + kx * phi1)), self.phi1_offset_m)

    def _pieces(self, t0: float, t1: float, delay: float) -> list[tuple[float, V | None]]:
        z = None
        cur: V | None = z
        out: list[tuple[float, V | None]] = []
        tau = t0
        for ts, a in self._sent:
            t_on = ts + delay
            if t_on <= t0 + 1e-9:
                cur = a
                continue
            if t_on >= t1:
                break
            out.append((t_on - tau, cur))
            tau, cur = t_on, a
        out.append((t1 - tau, cur))
        return out

    def _advance(self, a_f: list[Arr], v: list[Arr], p: list[Arr], t0: float, t1: Any) -> None:
        """``t1``: one time, or one per flight (``_extrapolate`` with a horizon per flight)."""
        horizon = self.horizon_s
        if np.ndim(horizon) == 0 or bool(np.all(horizon == horizon[0])):  # one horizon: shared pieces
            h0 = float(horizon) if np.ndim(horizon) == 0 else float(horizon[0])
            t1_ = float(t1) if np.ndim(t1) == 0 else float(t1[0])
            self._shared_pieces(a_f, v, p, [(h, u_sp) for h, u_sp in self._pieces(t0, t1_, h0) if h > 0.0])
            return
        # a horizon per flight (the identification moved some): the scalar's pieces per flight,
        # the setpoint history walked once with masks (same breakpoints, same order per flight)
        n = self.n
        z = np.zeros(n)
        cur: list[Arr] = [z, z, z]
        tau = np.full(n, t0)
        done = np.zeros(n, dtype=bool)
        for ts, a in self._sent:
            t_on = ts + horizon
            before = ~done & (t_on <= t0 + 1e-9)
            done = done | (~before & (t_on >= t1))
            emit = ~before & ~done
            if emit.any():
                h = t_on - tau
                self._piece(a_f, v, p, h, tuple(cur), emit & (h > 0.0))  # type: ignore[arg-type]
                tau = np.where(emit, t_on, tau)
            take = before | emit
            if take.any():
                cur = [np.where(take, a[i], cur[i]) for i in range(3)]
            if done.all():
                break
        h = t1 - tau
        self._piece(a_f, v, p, h, tuple(cur), h > 0.0)  # type: ignore[arg-type]

    def _shared_pieces(self, a_f: list[Arr], v: list[Arr], p: list[Arr], pieces: list[tuple[float, V | None]]) -> None:
        """:meth:`_piece` for every flight, one ``h`` (> 0 s) per piece, the three axes stacked as
        (3, N) arrays: per element the same operations in the same order (the lag's exponential by
        ``math.exp`` on an axis with one lag, by NumPy on one with a lag per flight, as there)."""
        if not pieces:
            return
        n = self.n

        def stack(x: Any) -> Arr:
            a, b, c = x
            if type(a) is np.ndarray and type(b) is np.ndarray and type(c) is np.ndarray and a.shape == b.shape == c.shape == (n,):
                return np.array((a, b, c), dtype=float)
            return np.array([np.full(n, float(e)) if np.ndim(e) == 0 else e for e in (a, b, c)], dtype=float)

        acc_f, vel, pos = stack(a_f), stack(v), stack(p)
        gain, drag, dist = stack(self.gain), stack(self.drag), stack(self.disturbance)
        lags = self.lag
        scalar = all(np.ndim(lag) == 0 for lag in lags)
        if scalar:
            on_col = np.array([[float(lag) > 0.0] for lag in lags])
            every = bool(on_col.all())
        else:
            lag_on = stack([np.asarray(lag) > 0.0 for lag in lags]) > 0.0
            lag_c = [np.where(np.asarray(lag) > 0.0, lag, 1.0) for lag in lags]
        for h, u_sp in pieces:
            u = gain * (stack(u_sp) if u_sp is not None else 0.0)
            d = acc_f - u
            if scalar:
                alpha = [math.exp(-h / lag) if lag > 0.0 else 0.0 for lag in lags]
                k1 = np.array([[lag / h] for lag in lags])
                k2 = np.array([[1.0 - al] for al in alpha])
                mean_a = u + d * k1 * k2
                a_new = u + d * np.array([[al] for al in alpha])
                if not every:
                    hold = u + 0.0 * acc_f
                    mean_a, a_new = np.where(on_col, mean_a, hold), np.where(on_col, a_new, hold)
            else:
                alpha_rows, k1_rows = [], []
                for lag, lc in zip(lags, lag_c):
                    if np.ndim(lag) == 0:
                        alpha_rows.append(math.exp(-h / lag) if lag > 0.0 else 0.0)
                        k1_rows.append(lag / h if lag > 0.0 else 0.0)
                    else:
                        al = np.exp(-h / lc)
                        alpha_rows.append(al)
                        k1_rows.append(lc / h)
                alpha_a, k1_a = stack(alpha_rows), stack(k1_rows)
                hold = u + 0.0 * acc_f
                mean_a = np.where(lag_on, u + d * k1_a * (1.0 - alpha_a), hold)
                a_new = np.where(lag_on, u + d * alpha_a, hold)
            acc = mean_a - drag * vel + dist
            pos = pos + h * (vel + 0.5 * h * acc)
            vel = vel + h * acc
            acc_f = a_new
        for i in range(3):
            a_f[i], v[i], p[i] = acc_f[i], vel[i], pos[i]

    def _piece(self, a_f: list[Arr], v: list[Arr], p: list[Arr], h: Arr, u_sp: V | None, rows: Mask) -> None:
        """One zero-order-hold piece of ``_advance`` for the flights ``rows`` (``h`` per flight, > 0 s
        there); one ``h`` for every flight goes through :meth:`_shared_pieces`."""
        if not rows.any():
            return
        h = np.where(rows, h, 1.0)
        for i in range(3):
            u = self.gain[i] * (u_sp[i] if u_sp is not None else 0.0)
            lag = self.lag[i]
            pos = np.asarray(lag) > 0.0
            lag_ = np.where(pos, lag, 1.0)
            alpha = np.exp(-h / lag_)
            mean_a = np.where(pos, u + (a_f[i] - u) * (lag_ / h) * (1.0 - alpha), u + 0.0 * a_f[i])
            a_new = np.where(pos, u + (a_f[i] - u) * alpha, u + 0.0 * a_f[i])
            acc = mean_a - self.drag[i] * v[i] + self.disturbance[i]
            p_new = p[i] + h * (v[i] + 0.5 * h * acc)
            v_new = v[i] + h * acc
            a_f[i], p[i], v[i] = np.where(rows, a_new, a_f[i]), np.where(rows, p_new, p[i]), np.where(rows, v_new, v[i])

    def predict(self, time_s: float, position: V, velocity: V) -> tuple[V, V]:
        t_prev = self._t
        if t_prev is not None and time_s <= t_prev:
            return self._extrapolate(time_s, position, velocity)
        if t_prev is None or time_s - t_prev > MAX_GAP_S:
            self.reset()
            self._t = time_s
            self._v_hat = velocity
            return self._extrapolate(time_s, position, velocity)
        dt = time_s - t_prev
        a_f, vh, ph = list(self._a_f), list(self._v_hat), [0.0, 0.0, 0.0]
        self._advance(a_f, vh, ph, t_prev, time_s)  # type: ignore[arg-type]
        w = self.observer_rad_s
        l1, l2 = 2.0 * w * dt, w * w * dt
        dmax = self.max_disturbance_m_s2
        dh = list(self.disturbance)
        for i in range(3):
            e = velocity[i] - vh[i]
            vh[i] = vh[i] + l1 * e
            d = dh[i] + l2 * e
            dh[i] = np.where(d > dmax, dmax, np.where(d < -dmax, -dmax, d))
        self._a_f = (a_f[0], a_f[1], a_f[2])
        self._v_hat = (vh[0], vh[1], vh[2])
        self.disturbance = (dh[0], dh[1], dh[2])
        self._t = time_s
        if self.identifier is not None:
            self._adapt(t_prev, time_s, velocity)
        return self._extrapolate(time_s, position, velocity)

    def _adapt(self, t_prev: float, time_s: float, velocity: V) -> None:
        """``InnerLoopCompensator._adapt`` per flight."""
        assert self.identifier is not None
        prev_active = self.identifier.active
        found = self.identifier.update(time_s, velocity, self._pieces)  # type: ignore[arg-type]
        if found is not None:
            adopt, lag, delay = found
            if adopt.any():  # the guard watches each adoption against the model flown until now
                w = lambda new, old: np.where(adopt, new, old)  # noqa: E731
                self._w_on, self._w_t0 = self._w_on | adopt, w(time_s, self._w_t0)
                self._w_ref_c, self._w_ref_s = w(self._slow_cross_ms, self._w_ref_c), w(self._slow_speed_ms, self._w_ref_s)
                now = (self.lag[0], self.horizon_s, *self.gain, *self.drag)
                self._w_before = tuple(w(x, old) for x, old in zip(now, self._w_before))
                self._w_ident = tuple(w(x, old) for x, old in zip(self._identified, self._w_ident))
                self._w_prev, self._w_cand = w(prev_active, self._w_prev), w(self.identifier.active, self._w_cand)
                self._w_target = (w(self._target[0], self._w_target[0]), w(self._target[1], self._w_target[1]))
                self._restoring = self._restoring & ~adopt
            self._target = (np.where(adopt, lag, self._target[0]), np.where(adopt, delay, self._target[1]))
            if adopt.any():
                gain = self.identifier.gain_xy
                gz, cz = self.identifier.vertical
                new = (lag, delay, self.identifier.drag_1_s, np.full(self.n, time_s), np.where(np.isnan(gain), 1.0, gain),
                       np.where(np.isnan(gz), self.gain[2], gz), np.where(np.isnan(cz), self.drag[2], cz))  # fmt: skip
                self._identified = tuple(np.where(adopt, x, old) for x, old in zip(new, self._identified))
                self._drag_f = np.where(adopt, self.identifier.drag_1_s, self._drag_f)
        dt = time_s - t_prev
        dtv = np.where(time_s < self._rollback_until, dt * GUARD_SLEW_FACTOR, dt)
        rows = ~np.isnan(self._target[0]) & ~self._restoring
        if rows.any():
            ident = self.identifier
            live, (gz, cz) = ident.drag_1_s, ident.vertical
            c = min(1.0, dt / DRAG_FOLLOW_S)
            f = np.where(np.isnan(self._drag_f), live, self._drag_f + c * (live - self._drag_f))
            follow = rows & ~np.isnan(live) & np.isnan(cz)  # a bank candidate's drag (a joint one's: as it is)
            self._drag_f = np.where(follow, f, self._drag_f)
            drag = np.where(follow, f, live)
            gain = ident.gain_xy
            still = ~np.isnan(cz) & ~ident.moving  # a joint fit while hovering: what is flown stays
            if still.any():
                drag, gain, gz, cz = (np.where(still, math.nan, x) for x in (drag, gain, gz, cz))
            self._move_to_target(dtv, rows, self._target, drag, gain, (gz, cz))  # type: ignore[arg-type]
        if self._restoring.any():  # rolled back to the initial model
            r = self._r
            self._move_to_target(dtv, self._restoring, (r[0], r[1]), r[5], r[2], (r[4], r[7]))  # type: ignore[arg-type]

    def watch(self, time_s: float, cross_track_m: Arr, speed_error_m_s: Arr) -> None:
        """``InnerLoopCompensator.watch`` per flight."""
        if self.identifier is None:
            return
        t_prev, self._err_t = self._err_t, time_s
        e2, s2 = cross_track_m * cross_track_m, speed_error_m_s * speed_error_m_s
        if t_prev is None:
            self._cross_ms = self._slow_cross_ms = e2
            self._speed_ms = self._slow_speed_ms = s2
            return
        dt = time_s - t_prev
        if not 0.0 < dt <= MAX_GAP_S:
            return
        c = dt / GUARD_TIME_S if dt < GUARD_TIME_S else 1.0
        self._cross_ms = self._cross_ms + c * (e2 - self._cross_ms)
        self._speed_ms = self._speed_ms + c * (s2 - self._speed_ms)
        c = dt / GUARD_REFERENCE_TIME_S if dt < GUARD_REFERENCE_TIME_S else 1.0
        self._slow_cross_ms = self._slow_cross_ms + c * (e2 - self._slow_cross_ms)
        self._slow_speed_ms = self._slow_speed_ms + c * (s2 - self._slow_speed_ms)
        on = self._w_on & ~(time_s - self._w_t0 > GUARD_WATCH_S)
        self._w_on = on
        if not on.any():
            return
        self._w_ref_c = np.where(on & (self._slow_cross_ms < self._w_ref_c), self._slow_cross_ms, self._w_ref_c)
        self._w_ref_s = np.where(on & (self._slow_speed_ms < self._w_ref_s), self._slow_speed_ms, self._w_ref_s)
        cross, ref = np.sqrt(self._cross_ms), np.sqrt(np.where(on, self._w_ref_c, 0.0))
        fire = on & ~(cross <= GUARD_RATIO * ref + GUARD_MARGIN_M)
        if not fire.any():
            return
        assert self.identifier is not None
        for i in np.flatnonzero(fire):
            prev = int(self._w_prev[i])
            self.identifier.flights[i].reject(int(self._w_cand[i]), None if prev < 0 else prev)
        m = self._identified
        f = lambda new, old: np.where(fire, new, old)  # noqa: E731
        rb = (np.full(self.n, time_s), m[1], m[4], m[2], m[3], cross, ref, np.sqrt(self._speed_ms))
        self._rb = tuple(f(x, old) for x, old in zip(rb, self._rb))
        initial = fire & (self._w_prev < 0)
        self._restoring = self._restoring | initial
        self._r = tuple(np.where(initial, b, r) for b, r in zip(self._w_before, self._r))
        b = self._w_before
        self._target = (f(np.where(initial, b[0], self._w_target[0]), self._target[0]),
                        f(np.where(initial, b[1], self._w_target[1]), self._target[1]))  # fmt: skip
        self._identified = tuple(f(x, old) for x, old in zip(self._w_ident, self._identified))
        self._rollback_until = f(time_s + GUARD_SLEW_S, self._rollback_until)
        self._w_on = on & ~fire

    def rolled_back(self) -> dict[str, Arr] | None:
        """``InnerLoopCompensator.rolled_back`` per flight (NaN where the guard never fired): when,
        the rejected model's dead time, gain, drag and adoption time, the low-passed cross-track
        RMS that fired it, its reference, the speed error's RMS then."""
        if self.identifier is None:
            return None
        keys = ("at_s", "delay_s", "gain_xy", "drag_1_s", "adopted_at_s", "cross_track_rms_m", "reference_cross_track_rms_m",
                "speed_error_rms_m_s")  # fmt: skip
        return dict(zip(keys, self._rb))

    def _move_to_target(self, dt: float | Arr, rows: Mask, target: tuple[Arr, Arr], drag: Arr, gain: Arr,
                        vertical: tuple[Arr, Arr]) -> None:  # fmt: skip
        """``InnerLoopCompensator._move_to_target`` for the flights ``rows`` (drag, gain, vertical
        NaN: none)."""
        gain_step, drag_step = ADAPT_GAIN_SLEW * dt, ADAPT_DRAG_SLEW * dt
        drag_before = self.drag
        has_gain = rows & ~np.isnan(gain)
        cur_gain = self.gain[0]
        new_gain = np.where(has_gain, cur_gain + np.maximum(-gain_step, np.minimum(gain_step, gain - cur_gain)), cur_gain)
        self.gain = (new_gain, new_gain, self.gain[2])
        gz_t, cz_t = vertical
        has_z = rows & ~np.isnan(gz_t) if ADOPT_VERTICAL else np.zeros(self.n, dtype=bool)
        gz, cz = self.gain[2], self.drag[2]
        gz = np.where(has_z, gz + np.maximum(-gain_step, np.minimum(gain_step, gz_t - gz)), gz)
        cz = np.where(has_z, cz + np.maximum(-drag_step, np.minimum(drag_step, cz_t - cz)), cz)
        self.gain = (self.gain[0], self.gain[1], gz)
        self.drag = (self.drag[0], self.drag[1], cz)
        step = ADAPT_SLEW * dt
        lag, delay = target
        cur_lag, cur_delay = self.lag[0], self.horizon_s
        new_lag = cur_lag + np.maximum(-step, np.minimum(step, lag - cur_lag))
        new_delay = cur_delay + np.maximum(-step, np.minimum(step, delay - cur_delay))
        new_lag = np.where(rows, new_lag, cur_lag)
        lag_z, cur_lag_z = vertical_lag(self.c.model, delay), self.lag[2]
        new_lag_z = np.where(rows, cur_lag_z + np.maximum(-step, np.minimum(step, lag_z - cur_lag_z)), cur_lag_z)
        self.lag = (new_lag, new_lag, new_lag_z)
        has = rows & ~np.isnan(drag)
        cur = self.drag[0]
        new_drag = np.where(has, cur + np.maximum(-drag_step, np.minimum(drag_step, drag - cur)), cur)
        self.drag = (new_drag, new_drag, self.drag[2])
        # InnerLoopCompensator._hand_over_drag (where the drag did not move: + 0, the same d̂)
        c, v, d, dmax = self.drag, self._v_hat, self.disturbance, self.max_disturbance_m_s2
        self.disturbance = tuple(np.minimum(dmax, np.maximum(-dmax, d[i] + (c[i] - drag_before[i]) * v[i])) for i in range(3))  # type: ignore[assignment]
        self.horizon_s = np.where(rows, new_delay, cur_delay)  # delay_s = delay_z_s = horizon_s, no hold (equal already)

    def identified(self) -> dict[str, Arr] | None:
        """``InnerLoopCompensator.identified`` per flight (NaN where nothing was adopted)."""
        if self.identifier is None:
            return None
        return dict(zip(("lag_s", "delay_s", "drag_1_s", "adopted_at_s", "gain_xy", "gain_z", "drag_z_1_s"), self._identified))

    def _extrapolate(self, time_s: float, position: V, velocity: V) -> tuple[V, V]:
        if np.all(self.horizon_s <= 0.0):
            return position, velocity
        a_f, v, p = list(self._a_f), list(velocity), list(position)
        self._advance(a_f, v, p, time_s, time_s + self.horizon_s)
        return (p[0], p[1], p[2]), (v[0], v[1], v[2])

    def lead(self, accel: V, jerk: V) -> V:
        lag = self.lag
        return (accel[0] + lag[0] * jerk[0], accel[1] + lag[1] * jerk[1], accel[2] + lag[2] * jerk[2])

    def invert(self, accel: V, velocity_pred: V, velocity_ref: V) -> V:
        """``InnerLoopCompensator.invert`` with its reference velocity (``drag_velocity``)."""
        d, c = self.disturbance, self.drag
        vd = []
        for i in range(3):
            ci = np.asarray(c[i], dtype=float)
            dv = velocity_pred[i] - velocity_ref[i]
            with np.errstate(divide="ignore"):
                lim = np.where(ci > 0.0, MAX_DRAG_FEEDBACK_M_S2 / np.where(ci > 0.0, ci, 1.0), np.inf)
            vd.append(velocity_ref[i] + np.minimum(lim, np.maximum(-lim, dv)))
        b = [c[i] * vd[i] - d[i] for i in range(3)]
        v, r = velocity_pred, velocity_ref
        # overspeed_bounded, per flight
        sp2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        lim = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) + OVERSPEED_MARGIN_M_S
        fast = sp2 > lim * lim
        sp = np.sqrt(np.where(fast, sp2, 1.0))
        along = (b[0] * v[0] + b[1] * v[1] + b[2] * v[2]) / sp
        k = np.where(fast & (along > 0.0), along * (1.0 - lim / sp) / sp, 0.0)
        b = [np.where(k != 0.0, b[i] - k * v[i], b[i]) for i in range(3)]
        return ((accel[0] + b[0]) / self.gain[0], (accel[1] + b[1]) / self.gain[1], (accel[2] + b[2]) / self.gain[2])

    @property
    def holds(self) -> bool:
        return self.hold_s[0] > 0.0 or self.hold_s[2] > 0.0

    def outgoing(self, time_s: float) -> V:
        sent = self._sent
        if not sent:
            z = np.zeros(self.n)
            return (z, z, z)
        out = []
        for i in range(3):
            cutoff = time_s - self.hold_s[i] + 1e-9
            value = sent[0][1][i]
            for ts, a in sent:
                if ts > cutoff:
                    break
                value = a[i]
            out.append(value)
        return (out[0], out[1], out[2])

    def commit(self, time_s: float, setpoint: V, clip: Any) -> V:
        def feasible(a: V) -> V:
            fc = clip((a[0], a[1], a[2] + G))
            return (fc[0], fc[1], fc[2] - G)

        sent = feasible(setpoint)
        self.record(time_s, sent)
        return feasible(self.outgoing(time_s)) if self.holds else sent

    def record(self, time_s: float, setpoint: V) -> None:
        sent = self._sent
        if sent and time_s < sent[-1][0]:
            return
        sent.append((time_s, setpoint))
        horizon = time_s - self._history_s
        while len(sent) > 1 and sent[1][0] <= horizon:
            sent.pop(0)


class _StartRamp:
    """The scalar follower's start ramp (``PathFollower._ramp``, when the scalar follower has one)
    for N flights: the reference speed rises as ``sqrt(v0^2 + 2 a s)`` over the distance ``s``
    travelled along the path since activation, until it reaches the reference (then done)."""

    def __init__(self, ramp: Any, n: int) -> None:
        self.accel = ramp.accel
        self.lap = ramp.lap
        self.sign = ramp.sign
        self.n = n
        self.reset()

    def reset(self) -> None:
        n = self.n
        self.done = np.full(n, self.accel is None)
        self._eta1 = np.full(n, math.nan)  # NaN: not started (the scalar's None)
        self._s = np.zeros(n)
        self._v0 = np.zeros(n)

    def _travelled(self, eta1: Arr) -> Arr:
        d = eta1 - self._eta1
        if self.lap is not None:
            half = 0.5 * self.lap
            d = np.mod(d + half, self.lap) - half
        s = self._s + self.sign * d
        return np.where(s > 0.0, s, 0.0)

    def advance(self, eta1: Arr, speed_along: Arr, rows: Mask) -> None:
        rows = rows & ~self.done
        start = rows & np.isnan(self._eta1)
        v0 = self.sign * speed_along
        self._v0 = np.where(start, np.where((v0 > 0.0) & np.isfinite(v0), v0, 0.0), self._v0)
        self._s = np.where(start, 0.0, np.where(rows, self._travelled(eta1), self._s))
        self._eta1 = np.where(rows, eta1, self._eta1)

    def speed(self, eta1: Arr) -> Arr:
        """|eta2_ref| the ramp allows (NaN: none — done or not started)."""
        if self.accel is None:
            return np.full(self.n, math.nan)
        on = ~self.done & ~np.isnan(self._eta1)
        v = np.sqrt(self._v0 * self._v0 + 2.0 * self.accel * self._travelled(eta1))
        return np.where(on, v, math.nan)


class BatchFollower:
    """N copies of a scalar :class:`~pf_offboard.control.PathFollower` (its path, gains, limits,
    yaw, speed profile, compensator), stepped together: :meth:`update` takes positions and
    velocities of shape (N, 3) and returns a :class:`BatchCommand`."""

    def __init__(self, follower: Any, n: int, per_flight: list[Any] | None = None) -> None:
        if follower.feedforward != "on_path":
            raise NotImplementedError("the batch engine mirrors feedforward: on_path only (any_state: use --engine scalar)")
        self.scalar = follower
        self.n = n
        self.path = follower.path
        self.bpath = BatchPath(follower.path)
        self.projector = BatchProjector(follower.path, n, self.bpath)
        # per_flight: one scalar ControlLaw (or follower) per row, differing from ``follower``'s in its gains only
        laws = None if per_flight is None else [getattr(f, "law", f) for f in per_flight]
        self.law = BatchLaw(follower.gains, follower.limits, laws)
        self.speed = follower.speed
        self.profile = _Profile(follower.profile) if follower.profile is not None else None
        # the identified response's profile, blended in per flight from its adoption (the scalar's)
        ident = getattr(follower, "identified_profile", None)
        self.identified_profile = _Profile(ident) if ident is not None and self.profile is not None else None
        t0 = getattr(follower, "_replan_t0", None)
        self._replan_t0 = np.full(n, math.nan if t0 is None else float(t0))
        self._replan_w = np.full(n, float(getattr(follower, "_replan_w", 0.0)))
        self._replan_target = np.full(n, bool(getattr(follower, "_replan_target", False)))
        self._replan_from = np.full(n, float(getattr(follower, "_replan_from", 0.0)))
        self.compensator = _Compensator(follower.compensator, n) if follower.compensator is not None else None
        self._measured_projector = BatchProjector(follower.path, n, self.bpath) if self.compensator is not None else None
        self._yaw = follower._yaw
        self._held_yaw = np.full(n, float(follower._yaw.offset))  # YawSpec.hold: each flight's heading at activation
        ramp = getattr(follower, "_ramp", None)
        self._ramp = _StartRamp(ramp, n) if ramp is not None else None
        self._closed = bool(follower.path.closed)
        self._lam_max = float(follower.path.lam_max)
        self._length = float(follower.path.length_m)

    def hold_heading(self, yaw_rad: Arr) -> bool:
        """The scalar's hold_heading per flight (``hold`` yaw only; NaN rows keep their heading)."""
        if self._yaw.mode != "hold":
            return False
        yaw = np.asarray(yaw_rad, dtype=float)
        ok = np.isfinite(yaw)
        wrapped = np.array([math.remainder(x, 2.0 * math.pi) if math.isfinite(x) else 0.0 for x in yaw.tolist()])
        self._held_yaw = np.where(ok, wrapped, self._held_yaw)
        return True

    def reset(self) -> None:
        self.projector.reset()
        if self._ramp is not None:
            self._ramp.reset()
        if self.compensator is not None:
            self.compensator.reset()
            self._measured_projector.reset()  # type: ignore[union-attr]

    # ------------------------------------------------------------------ exact coordinates
    def _terms(self, y: V, v: V, projector: BatchProjector | None = None) -> tuple[Arr, tuple[Arr, ...], Terms]:
        lam = (projector or self.projector).update(*y)
        return (lam, *self.terms_at(lam, y, v))

    def terms_at(self, lam: Arr, y: V, v: V) -> tuple[tuple[Arr, ...], Terms]:
        """:func:`pf_offboard.control.follower.evaluate_terms` at given parameters."""
        bp = self.bpath
        s = bp.eval_floats(lam)
        (_, _, _), (e2, de2, dde2), (e3, de3, dde3) = bp.frame_jets(lam, s)
        terms = exact_terms(bp.arclength(lam), s[0:3], s[3:6], s[6:9], s[9:12], e2, de2, dde2, e3, de3, dde3, y, v)
        return s, terms

    # ------------------------------------------------------------------ control
    def reference(self, eta1: Arr) -> tuple[Arr, Arr, Arr]:
        """``PathFollower.reference`` (and ``reference_speed``)."""
        law = self.law
        z = np.zeros_like(eta1)
        if self.profile is None:
            if self._closed:
                return np.full_like(eta1, self.speed), z, z
            ahead = self._length - eta1 if self.speed > 0.0 else eta1
            stop = law.stopping_speed(ahead)
            return np.where(abs(self.speed) <= stop, self.speed, np.copysign(stop, self.speed)), z, z
        e, de, dde = self.profile.evaluate(eta1)
        if self.identified_profile is not None and (self._replan_w > 0.0).any():
            w = self._replan_w
            e1, de1, dde1 = self.identified_profile.evaluate(eta1)
            k = 1.0 - w
            e, de, dde = k * e + w * e1, k * de + w * de1, k * dde + w * dde1
        if self._closed:
            return e, de, dde
        sign = 1.0 if self.speed > 0.0 else -1.0
        ahead = self._length - eta1 if sign > 0.0 else eta1
        stop = law.stopping_speed(ahead)
        keep = stop >= np.abs(e)
        past = ahead <= 0.0
        lin = law.k_pos_t * ahead
        linear = lin <= stop
        st = np.where(stop > 0.0, stop, 1.0)
        a_dec = law.a_dec
        e_s = np.where(past, 0.0, sign * stop)
        de_s = np.where(past, 0.0, np.where(linear, -law.k_pos_t, -a_dec / st))
        dde_s = np.where(past | linear, 0.0, sign * -a_dec * a_dec / power(st, 3.0))
        return np.where(keep, e, e_s), np.where(keep, de, de_s), np.where(keep, dde, dde_s)

    def _evaluate(self, y: V, v: V, lam: Arr, s: tuple[Arr, ...], terms: Terms,
                  offsets: tuple[Arr, Arr, Arr] | None) -> tuple[Any, ...]:  # fmt: skip
        """``PathFollower._evaluate``."""
        eta2_ref, deta2, ddeta2 = self.reference(terms.eta1)
        ff = deta2 * terms.eta2 if self.profile is not None else None
        cap = None
        if self._ramp is not None:  # the start ramp: its speed, feed-forward and bound where it is below the reference
            ff = deta2 * terms.eta2
            ramp = self._ramp.speed(terms.eta1)
            on = ~np.isnan(ramp) & (ramp < np.abs(eta2_ref))
            a = self._ramp.accel if self._ramp.accel is not None else math.inf
            cap = np.where(on, a, math.inf)
            fade = np.minimum(1.0, (np.abs(eta2_ref) - ramp) / (a * F.RAMP_END_S))
            ff = np.where(on, self._ramp.sign * a * fade, ff)
            eta2_ref = np.where(on, np.copysign(ramp, eta2_ref), eta2_ref)
            deta2 = np.where(on, 0.0, deta2)
            ddeta2 = np.where(on, 0.0, ddeta2)
        r = (y[0] - s[0], y[1] - s[1], y[2] - s[2])
        dist = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        w = _approach_weight(terms.tube, dist)
        past_end = np.zeros(len(lam), dtype=bool)
        if not self._closed:
            at_end = (lam <= 0.0) | (lam >= self._lam_max)
            out = np.where(lam > 0.0, terms.tangential_offset_m, -terms.tangential_offset_m)
            hit = at_end & (out > 0.0)
            past_end = hit & ((lam > 0.0) == (self.speed > 0.0))
            w = np.where(hit, np.maximum(w, out / F.END_BLEND_M), w)
        w = np.where(w <= 0.0, 0.0, np.where(w >= 1.0, 1.0, w))
        law = self.law
        eta2_ref_law = eta2_ref
        st = terms
        if offsets is not None:
            b_eta2, b_xi1, b_phi1 = offsets
            if not self._closed:  # the speed offset fades with the reference at an open path's end (as the scalar's)
                b_eta2 = np.where(np.abs(eta2_ref) < abs(self.speed), b_eta2 * np.abs(eta2_ref) / abs(self.speed), b_eta2)
            use = w < 1.0
            eta2_ref_law = np.where(use, eta2_ref + b_eta2, eta2_ref)
            terms = terms._replace(xi1=np.where(use, terms.xi1 + b_xi1, terms.xi1), phi1=np.where(use, terms.phi1 + b_phi1, terms.phi1))
        tube, ok = law.tube(terms, eta2_ref_law, ff, tangential_cap=cap)
        has_tube = (w < 1.0) & ok
        w = np.where(has_tube, w, 1.0)
        tan, s_ss, s_sss = onpath_derivatives(s[3:6], s[6:9], s[9:12])
        app = law.approach(r, v, tan, np.where(past_end, 0.0, eta2_ref), cap)
        k = 1.0 - w
        blend = (k * tube.accel[0] + w * app.accel[0], k * tube.accel[1] + w * app.accel[1], k * tube.accel[2] + w * app.accel[2])
        only_app = w >= 1.0  # no tube output (w = 1) or the approach alone
        only_tube = w <= 0.0
        acc = _where3(only_app, app.accel, _where3(only_tube, tube.accel, blend))
        res = LawOut(
            acc,
            np.where(only_app, app.tangential, np.where(only_tube, tube.tangential, tube.tangential | app.tangential)),
            np.where(only_app, app.transversal, np.where(only_tube, tube.transversal, tube.transversal | app.transversal)),
            np.where(only_app, app.approach_speed, np.where(only_tube, tube.approach_speed, tube.approach_speed | app.approach_speed)),
        )
        return st, eta2_ref, deta2, ddeta2, w, res, tan, s_ss, s_sss, dist

    def _onpath_jerk(self, e: Arr, de: Arr, dde: Arr, w: Arr, tan: V, ss: V, s_sss: V) -> V:
        k3 = (1.0 - w) * e * e * e
        jerk = (s_sss[0] * k3, s_sss[1] * k3, s_sss[2] * k3)
        if self.profile is None:
            return jerk
        k2 = (1.0 - w) * 3.0 * e * e * de
        k1 = (1.0 - w) * e * (dde * e + de * de)
        t = tan
        return (jerk[0] + ss[0] * k2 + t[0] * k1, jerk[1] + ss[1] * k2 + t[1] * k1, jerk[2] + ss[2] * k2 + t[2] * k1)

    def _yaw_evaluate(self, eta1: Arr, tan: V, ss: V) -> tuple[Arr, Arr]:
        yp = self._yaw
        if yp.mode == "constant":
            return np.full_like(eta1, yp.offset), np.zeros_like(eta1)
        if yp.mode == "hold":
            return self._held_yaw.copy(), np.zeros_like(eta1)
        if yp.mode == "table":  # the scalar table per flight (a pure function of eta1)
            tab = np.array([yp._table(e) for e in eta1.tolist()]).reshape(-1, 2)
            return tab[:, 0], tab[:, 1]
        hx = yp.direction * tan[0]
        hy = yp.direction * tan[1]
        n2 = hx * hx + hy * hy
        psi = atan2(hy, hx) + yp.offset
        vert = n2 < 1e-6
        dpsi = (tan[0] * ss[1] - tan[1] * ss[0]) / np.where(vert, 1.0, n2)
        return psi, np.where(vert, 0.0, dpsi)

    def update(self, position: Arr, velocity: Arr, time_s: float | None = None) -> BatchCommand:
        """``PathFollower.update`` for every flight: positions and velocities (N, 3), ENU."""
        y: V = (position[:, 0].astype(float), position[:, 1].astype(float), position[:, 2].astype(float))
        v: V = (velocity[:, 0].astype(float), velocity[:, 1].astype(float), velocity[:, 2].astype(float))
        comp = self.compensator if time_s is not None else None
        y_meas, v_meas = y, v
        with np.errstate(all="ignore"):
            if comp is not None:
                t_s = float(time_s)  # type: ignore[arg-type]
                y, v = comp.predict(t_s, y, v)
                bad = ~np.all(np.isfinite(np.array(y + v)), axis=0)
                if bad.any():
                    raise FloatingPointError("batch compensator: a non-finite prediction (the scalar one resets here)")
                if self.identified_profile is not None and comp.identifier is not None:
                    # PathFollower._replans: an adoption with the model's lag
                    adopted = ~np.isnan(comp._identified[3]) & (comp._identified[0] <= self.scalar.vehicle.accel_lag_xy_s + 1e-9)
                    switch = adopted != self._replan_target  # blended in from an adoption, out after a rollback
                    self._replan_from = np.where(switch, self._replan_w, self._replan_from)
                    self._replan_t0 = np.where(switch, t_s, self._replan_t0)
                    self._replan_target = adopted
                    x = np.clip((t_s - self._replan_t0) / REPLAN_BLEND_S, 0.0, 1.0)
                    k, target = x * x * (3.0 - 2.0 * x), adopted.astype(float)
                    self._replan_w = np.where(np.isnan(self._replan_t0), 0.0, self._replan_from + (target - self._replan_from) * k)
                # as the scalar: the measured state's closest point first, the law's searched from it
                lam_meas = self._measured_projector.update(*y_meas)  # type: ignore[union-attr]
                self.projector.seed(lam_meas, *y, *y_meas)
            lam, s, terms = self._terms(y, v)
            ramp = self._ramp
            if ramp is not None and not ramp.done.all():
                d1 = s[3:6]
                n1 = np.sqrt(d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2])
                eta1 = terms.eta1
                rows = ~ramp.done
                ramp.advance(eta1, (v[0] * d1[0] + v[1] * d1[1] + v[2] * d1[2]) / n1, rows)
                allowed = ramp.speed(eta1)
                ramp.done = ramp.done | (rows & ~np.isnan(allowed) & (allowed >= np.abs(self.reference(eta1)[0]) - F.RAMP_DONE_M_S))
            offsets = comp.integral_offsets() if comp is not None else None
            st, eta2_ref, deta2, ddeta2, w, res, tan, s_ss, s_sss, dist = self._evaluate(y, v, lam, s, terms, offsets)
            law = self.law
            ax, ay, az = res.accel
            jerk = self._onpath_jerk(eta2_ref, deta2, ddeta2, w, tan, s_ss, s_sss)
            if comp is not None:
                v_ref = (tan[0] * eta2_ref, tan[1] * eta2_ref, tan[2] * eta2_ref)
                sp = comp.invert(comp.lead((ax, ay, az), jerk), v, v_ref)
                ax, ay, az = comp.commit(t_s, sp, law.thrust_set.clip)
                zero = np.zeros_like(ax)
                jerk_rates: V = (zero, zero, zero)
            else:
                jerk_rates = jerk
            f = (ax, ay, az + G)
            thrust = np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
            tilt, thrust_sat = law.thrust_set.active(f)
            psi, dpsi = self._yaw_evaluate(st.eta1, tan, s_ss)
            eta2 = _blended_speed(st.eta2, w, tan, v)
            yaw_rate = dpsi * eta2
            axes = attitude_from_thrust(f, psi)
            q = quaternion_from_axes(*axes)
            omega = body_rates(axes, thrust, jerk_rates, yaw_rate)
            finite = np.all(np.isfinite(np.array((ax, ay, az, *q, *omega, thrust, psi, yaw_rate))), axis=0)
            if comp is not None:
                lam = lam_meas
                sm, mt = self.terms_at(lam, y_meas, v_meas)
                dist = np.sqrt((y_meas[0] - sm[0]) ** 2 + (y_meas[1] - sm[1]) ** 2 + (y_meas[2] - sm[2]) ** 2)
                t_m = sm[3:6]
                n_t = np.sqrt(t_m[0] * t_m[0] + t_m[1] * t_m[1] + t_m[2] * t_m[2])
                w_m = np.minimum(_approach_weight(mt.tube, dist), 1.0)
                st = mt._replace(eta2=_blended_speed(mt.eta2, w_m, (t_m[0] / n_t, t_m[1] / n_t, t_m[2] / n_t), v_meas))
                free = (w == 0.0) & ~(res.tangential | res.transversal | tilt | thrust_sat)
                comp.integrate(t_s, eta2_ref - st.eta2, st.xi1, st.phi1, free)
                comp.watch(t_s, dist, eta2_ref - st.eta2)
                # reported at the measured arclength (PathFollower._reference_at)
                e_m = self.reference(st.eta1)[0]
                r_m = ramp.speed(st.eta1) if ramp is not None else np.full_like(e_m, math.nan)
                eta2_ref = np.where(~np.isnan(r_m) & (r_m < np.abs(e_m)), np.copysign(r_m, e_m), e_m)
            a = np.fmod(psi + math.pi, 2.0 * math.pi)
            yaw = np.where(a <= 0.0, a + 2.0 * math.pi, a) - math.pi  # frames.wrap_pi
        return BatchCommand(
            np.stack((ax, ay, az), axis=1), thrust, np.stack(q, axis=1), np.stack(omega, axis=1), yaw, yaw_rate,
            st.eta1, st.eta2, st.xi1, st.xi2, st.phi1, st.phi2, lam, dist,
            res.tangential, res.transversal, tilt, thrust_sat, res.approach_speed, eta2_ref, finite,
        )  # fmt: skip
