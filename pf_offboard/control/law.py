"""The control law: TFL (eqs. 21-23) with limits, transversal correction first.

Near the path the transversal law is the paper's linear PD ``u = -kp e - kd e_dot`` on
``e = (xi1, phi1)``. It is written in nested form ``u = kd (v_d(e) - e_dot)`` with
``v_d = -(kp/kd) e``; far from the path the desired approach speed ``|v_d|`` is limited by
``max_approach_speed`` and by ``sqrt(2 a_dec |e|)`` (arrive without overshoot), and ``|u|`` by the
acceleration every direction can deliver. The tangential law is the velocity loop
``u_eta = kd_t (eta2_ref - eta2)``; its magnitude is bounded only when the caller passes a cap
(the follower does during its start ramp, ``limits.max_tangential_accel_m_s2``).

Slew limit (``limits.max_tilt_rate_rad_s``, jerk ``J = g * rate``): both velocity loops become
square-root controllers beyond ``|dv| = J/k^2`` and the approach-speed profile is bounded by
``(2J)^(1/3) (|e|/kappa)^(2/3)``, so the demand never swings faster than the vehicle can tilt; the
paper's linear laws act unchanged in a small neighbourhood of the path (docs/controller.md).
Time-invariant: no state.

Priority allocation in acceleration space: with ``M = beta^-1`` (columns m1, m2, m3),
``a = -M alpha + m2 u_xi + m3 u_phi + m1 u_eta``. The feasible thrust set is convex, so the
``u_eta`` that keep ``a`` feasible form one interval: u_eta is clipped into it. If the interval is
empty the transversal correction is scaled down (bisection) until it is not.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from pf_offboard.control.feasible import ThrustSet
from pf_offboard.control.transverse import ExactTerms, inverse_columns
from pf_offboard.control.types import GRAVITY_M_S2, Gains, Limits

Vec = tuple[float, float, float]
G = GRAVITY_M_S2

# Share of the guaranteed acceleration used to plan the approach deceleration (the rest is
# margin for the feedback and for the path's own curvature terms in alpha).
APPROACH_DECEL_SHARE = 0.5
BISECTION_STEPS = 16  # of the allocation's scalings (2^-16 of the correction)
# Braking reserve's gate (m/s): faster than the reference (along the direction of travel) by more
# than this, a tilt-saturated law keeps a share of the speed loop's braking, ramped from 0 here to
# BRAKING_RESERVE_SHARE at twice this (continuous in the state); the compensator's push scaling
# uses the same margin (compensator.OVERSPEED_MARGIN_M_S).
BRAKING_RESERVE_MARGIN_M_S = 0.25
BRAKING_RESERVE_SHARE = 0.5


def braking_reserve_share(eta2_ref: float, eta2: float) -> float:
    """Share of the speed loop's braking kept under a scaled-down transversal correction: 0 up
    to an overspeed ``|eta2| - |eta2_ref|`` of BRAKING_RESERVE_MARGIN_M_S, BRAKING_RESERVE_SHARE
    from twice that, linear between."""
    over = abs(eta2) - abs(eta2_ref) - BRAKING_RESERVE_MARGIN_M_S
    if over <= 0.0:
        return 0.0
    return BRAKING_RESERVE_SHARE * min(over / BRAKING_RESERVE_MARGIN_M_S, 1.0)


class LawOutput(NamedTuple):
    accel: Vec  # m/s^2 ENU, gravity excluded
    tangential: bool
    transversal: bool
    approach_speed: bool


class ControlLaw:
    """Pure: transverse terms (or an approach target) in, feasible acceleration out."""

    def __init__(self, gains: Gains, limits: Limits) -> None:
        self.gains = gains
        self.limits = limits
        self.kp = gains.transversal_kp
        self.kd = gains.transversal_kd
        self.k_pos = self.kp / self.kd  # 1/s: approach speed per metre of offset (linear region)
        self.kd_t = gains.tangential_kd
        self.k_pos_t = gains.tangential_kp / gains.tangential_kd
        self.thrust_set = ThrustSet(limits.min_thrust_m_s2, limits.max_thrust_m_s2, limits.tan_tilt)
        self.u_max = limits.guaranteed_accel_m_s2
        self.a_dec = APPROACH_DECEL_SHARE * self.u_max
        self.v_app = limits.max_approach_speed_m_s
        # Slew capability of the inner loops: jerk J = g * max_tilt_rate. The velocity loops
        # become square-root controllers above |dv| = J/k^2 (see shape()); inf: linear.
        rate = limits.max_tilt_rate_rad_s
        self.jerk = G * rate if rate is not None else math.inf
        self.dv_lin = self.jerk / (self.kd * self.kd)
        self.dv_lin_t = self.jerk / (self.kd_t * self.kd_t)
        # Position level: the approach speed may not change faster than the (scheduled) velocity
        # loop can follow: time scale e/v_d >= kappa * sqrt(v_d / 2J) with kappa = kd^2/kp (the
        # paper's ratio of the two loops' time scales in the linear region) gives
        # v_d <= (2J)^(1/3) (e/kappa)^(2/3); it meets the linear k_pos e at e_lin.
        kappa = self.kd * self.kd / self.kp
        self.c_cbrt = (2.0 * self.jerk) ** (1.0 / 3.0) / kappa ** (2.0 / 3.0) if math.isfinite(self.jerk) else math.inf

    def shape(self, k: float, dv_lin: float, dv: float) -> float:
        """Velocity-loop output magnitude for a velocity error ``dv >= 0``.

        ``k dv`` (the paper's linear gain) for ``dv <= dv_lin = J/k^2``, above that
        ``sqrt(2 J (dv - dv_lin/2))`` (C1 at the junction): the correction a loop with jerk J can
        remove without overshoot, i.e. the effective gain ``u/dv`` falls as ``sqrt(2J/dv)`` so a
        large error is corrected at a lower bandwidth the vehicle can slew, and its demand never
        swings faster than ``|du/dt| ~ J``.
        """
        if dv <= dv_lin:
            return k * dv
        return math.sqrt(2.0 * self.jerk * (dv - 0.5 * dv_lin))

    # ------------------------------------------------------------------ building blocks
    def approach_speed(self, dist_m: float) -> tuple[float, bool]:
        """Desired speed toward the target at distance ``dist_m`` and whether the speed limit binds."""
        lin = self.k_pos * dist_m
        brake = math.sqrt(2.0 * self.a_dec * dist_m)
        v = lin if lin < brake else brake
        if self.c_cbrt < math.inf:
            jerk = self.c_cbrt * dist_m ** (2.0 / 3.0)
            if jerk < v:
                v = jerk
        if self.v_app < v:
            return self.v_app, True
        return v, False

    def stopping_speed(self, dist_m: float) -> float:
        """Tangential speed limit that stops at the end of an open path ``dist_m`` ahead."""
        if dist_m <= 0.0:
            return 0.0
        lin = self.k_pos_t * dist_m
        brake = math.sqrt(2.0 * self.a_dec * dist_m)
        return lin if lin < brake else brake

    def transversal(self, xi1: float, xi2: float, phi1: float, phi2: float) -> tuple[float, float, bool, bool]:
        """(u_xi, u_phi, reduced, approach_limited) of the nested saturated PD."""
        d = math.hypot(xi1, phi1)
        if d > 0.0:
            speed, limited = self.approach_speed(d)
            k = speed / d
            vx, vy = -k * xi1, -k * phi1
        else:
            vx = vy = 0.0
            limited = False
        ex, ey = vx - xi2, vy - phi2
        dv = math.hypot(ex, ey)
        if dv <= self.dv_lin:
            ux, uy = self.kd * ex, self.kd * ey
            n = self.kd * dv
        else:
            n = self.shape(self.kd, self.dv_lin, dv)
            ux, uy = ex * (n / dv), ey * (n / dv)
        if n > self.u_max:
            k = self.u_max / n
            return ux * k, uy * k, True, limited
        return ux, uy, False, limited

    def tangential(self, eta2_ref: float, eta2: float, cap: float = math.inf) -> float:
        """u_eta of the tangential velocity loop (linear near eta2_ref, square-root beyond), at
        most ``cap`` in magnitude."""
        dv = eta2_ref - eta2
        if abs(dv) <= self.dv_lin_t:
            u = self.kd_t * dv
        else:
            u = math.copysign(self.shape(self.kd_t, self.dv_lin_t, abs(dv)), dv)
        return cap if u > cap else (-cap if u < -cap else u)

    # ------------------------------------------------------------------ the two laws
    def tube(
        self, terms: ExactTerms, eta2_ref: float, feedforward_m_s2: float = 0.0, bisection_steps: int = BISECTION_STEPS,
        tangential_cap: float = math.inf,
    ) -> LawOutput | None:
        """Exact TFL with limits inside the tube; None if beta is singular.

        ``feedforward_m_s2``: added to the tangential law's u_eta (a speed profile's or the start
        ramp's d(eta2_ref)/dt); ``tangential_cap``: bound on the speed loop's correction |u_eta|
        before that feed-forward (a saturation where it binds); ``bisection_steps``: of the allocation's scalings (the any-state
        feed-forward differentiates the law with more, so that it is smooth)."""
        cols = inverse_columns(terms.beta1, terms.beta2, terms.beta3)
        if cols is None:
            return None
        m1, m2, m3 = cols
        st = terms.state
        al1, al2, al3 = terms.alpha
        u_xi, u_phi, reduced, limited = self.transversal(st.xi1, st.xi2, st.phi1, st.phi2)
        u_eta = self.tangential(eta2_ref, st.eta2, tangential_cap)
        bounded = abs(u_eta) >= tangential_cap  # the start ramp's bound binds: a saturation too
        if feedforward_m_s2:
            u_eta += feedforward_m_s2
        # a_b: keeps (eta2, xi2, phi2) constant; a_t: transversal correction
        bx = -(m1[0] * al1 + m2[0] * al2 + m3[0] * al3)
        by = -(m1[1] * al1 + m2[1] * al2 + m3[1] * al3)
        bz = -(m1[2] * al1 + m2[2] * al2 + m3[2] * al3)
        tx = m2[0] * u_xi + m3[0] * u_phi
        ty = m2[1] * u_xi + m3[1] * u_phi
        tz = m2[2] * u_xi + m3[2] * u_phi
        ts = self.thrust_set
        mu = 1.0
        iv = ts.line_interval((bx + tx, by + ty, bz + tz + G), m1)
        if iv is None:
            # No room for the full transversal correction: scale it (mu) down until there is. If
            # even coasting (mu = 0) is infeasible, also scale the coasting term (nu) towards
            # hover, which is always feasible. Both scalings are continuous in the state.
            reduced = True
            if ts.line_interval((bx, by, bz + G), m1) is None:
                lo, hi = 0.0, 1.0
                for _ in range(bisection_steps):
                    mid = 0.5 * (lo + hi)
                    if ts.line_interval((mid * bx, mid * by, mid * bz + G), m1) is None:
                        hi = mid
                    else:
                        lo = mid
                bx, by, bz = lo * bx, lo * by, lo * bz
                mu = 0.0
            else:
                lo, hi = 0.0, 1.0
                for _ in range(bisection_steps):
                    mid = 0.5 * (lo + hi)
                    if ts.line_interval((bx + mid * tx, by + mid * ty, bz + mid * tz + G), m1) is None:
                        hi = mid
                    else:
                        lo = mid
                mu = lo
                share = braking_reserve_share(eta2_ref, st.eta2) if u_eta * st.eta2 < 0.0 else 0.0
                if share > 0.0:
                    # an overspeed beyond the gate while the speed loop brakes and the transversal
                    # correction is scaled down: keep a share of the braking. Giving all of the tilt
                    # to the correction left none to brake, and the overspeed kept the turn's demand
                    # over the tilt limit: a limit cycle (real PX4 SIH, 3 m/s helix: 38 cm RMS).
                    # Ungated (any braking) it also acted in ordinary tilt-saturated moments and
                    # flew worse on real PX4 (s36: 4.9-10.8 cm RMS vs 4.4-4.8).
                    want = share * u_eta
                    lo, hi = 0.0, mu
                    for _ in range(bisection_steps):
                        mid = 0.5 * (lo + hi)
                        ivm = ts.line_interval((bx + mid * tx, by + mid * ty, bz + mid * tz + G), m1)
                        if ivm is None or (ivm[0] > want if want < 0.0 else ivm[1] < want):
                            hi = mid
                        else:
                            lo = mid
                    mu = lo
            iv = ts.line_interval((bx + mu * tx, by + mu * ty, bz + mu * tz + G), m1)
            if iv is None:  # only through rounding at the bisection's end: fall back on the clip
                f = ts.clip((bx + mu * tx, by + mu * ty, bz + mu * tz + G))
                return LawOutput((f[0], f[1], f[2] - G), True, True, limited)
        clipped = False
        if u_eta < iv[0]:
            u_eta = iv[0]
            clipped = True
        elif u_eta > iv[1]:
            u_eta = iv[1]
            clipped = True
        a = (
            bx + mu * tx + m1[0] * u_eta,
            by + mu * ty + m1[1] * u_eta,
            bz + mu * tz + m1[2] * u_eta,
        )
        return LawOutput(a, clipped or bounded, reduced, limited)

    def approach(self, r: Vec, v: Vec, t: Vec, eta2_ref: float, tangential_cap: float = math.inf) -> LawOutput:
        """Cartesian law far from the path / outside the tube / past an open path's end.

        ``r = y - target`` (target: the closest point, or the end point), ``t`` the unit tangent
        there. Desired velocity: toward the target at :meth:`approach_speed` plus ``eta2_ref``
        along t. The correction across t has priority: it gets up to the guaranteed acceleration,
        the tangential correction the rest of that ball (so the result is always feasible).
        """
        d = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
        if d > 0.0:
            speed, limited = self.approach_speed(d)
            k = speed / d
        else:
            k, limited = 0.0, False
        ex = -k * r[0] - v[0]
        ey = -k * r[1] - v[1]
        ez = -k * r[2] - v[2]
        et = ex * t[0] + ey * t[1] + ez * t[2]
        # across t
        px, py, pz = ex - et * t[0], ey - et * t[1], ez - et * t[2]
        dv = math.sqrt(px * px + py * py + pz * pz)
        n = self.shape(self.kd, self.dv_lin, dv)
        if dv > 0.0:
            c = n / dv
            px, py, pz = px * c, py * c, pz * c
        reduced = False
        if n > self.u_max:
            c = self.u_max / n
            px, py, pz = px * c, py * c, pz * c
            n = self.u_max
            reduced = True
        # along t
        at = self.tangential(eta2_ref, -et, tangential_cap)
        room = math.sqrt(max(self.u_max * self.u_max - n * n, 0.0))
        clipped = abs(at) >= tangential_cap
        if at > room:
            at, clipped = room, True
        elif at < -room:
            at, clipped = -room, True
        f = self.thrust_set.clip((px + at * t[0], py + at * t[1], pz + at * t[2] + G))
        return LawOutput((f[0], f[1], f[2] - G), clipped, reduced, limited)
