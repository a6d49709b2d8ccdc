"""TrajectoryTracker: the trajectory-tracking baseline on the same spline (docs/evaluation.md).

What path following is compared with: the path is timed at constant speed along its arclength,
``s(t) = s0 + speed (t - t0)``, starting at the closest point when the controller is activated
(:meth:`TrajectoryTracker.reset`, then the first :meth:`~TrajectoryTracker.update`), and the
vehicle tracks the timed reference ``p_r(t) = sigma(s(t))`` with PD + acceleration feed-forward

    a = a_r + kp (p_r - y) + kd (v_r - v)     (near the reference)

with the path follower's transversal gains (same bandwidth / damping) on all three axes, written
in the same nested form ``a = a_r + kd (v_d - v)``, ``v_d = v_r - |v_d|(|e|) e/|e|``, so the same
:class:`~pf_offboard.control.types.Limits` act the same way: the approach speed toward the
reference, the slew limit (square-root velocity loop), the acceleration bound of the correction
and the tilt / thrust set (the feed-forward has priority: the correction is scaled into what
remains). Attitude, body-rate feed-forward (the reference's jerk) and yaw come from the same code
as the follower's (:mod:`pf_offboard.control.feedforward`); with a
:class:`~pf_offboard.control.compensator.InnerLoopCompensator` the same observer, delay predictor
(the law acts on the state at ``t + delay`` against the reference at ``t + delay``), inversion
and integral action apply, so both controllers see the same inner-loop model.

Unlike the path follower the law is time-varying: :meth:`update` needs each sample's time. On an
open path the timing brakes to a stop at the end with the law's approach deceleration. The
reported :class:`~pf_offboard.control.types.Command` ``state`` / ``cross_track_m`` / ``lam`` are
the measured transverse coordinates at the closest point, as the follower reports them.

Pure and I/O-free; world ENU z up, body FLU; m, m/s, m/s^2, s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from pf_offboard.control.compensator import InnerLoopCompensator
from pf_offboard.control.feedforward import (
    YawProfile,
    attitude_from_thrust,
    body_rates,
    onpath_derivatives,
    quaternion_from_axes,
)
from pf_offboard.control.follower import (
    MAX_POSITION_ABS_M,
    ControllerConfig,
    MAX_VELOCITY_ABS_M_S,
    PathFollower,
    _finite,
    _vec,
    evaluate_terms,
)
from pf_offboard.control.law import ControlLaw
from pf_offboard.control.types import GRAVITY_M_S2, Command, Compensation, Gains, Limits, Saturation, VehicleModel, YawSpec
from pf_offboard.errors import InputError
from pf_offboard.frames import wrap_pi

if TYPE_CHECKING:
    from pf_offboard.path import Path

G = GRAVITY_M_S2
Vec = tuple[float, float, float]


class Reference(NamedTuple):
    """The timed reference at one instant (world ENU)."""

    eta1_m: float  # arclength s(t) of the reference point
    lam: float  # its path parameter
    position_m: Vec  # sigma(s)
    velocity_m_s: Vec  # sigma_s * w
    accel_m_s2: Vec  # sigma_ss w^2 + sigma_s w_dot
    jerk_m_s3: Vec  # sigma_sss w^3 + 3 sigma_ss w w_dot (w_dot piecewise constant)
    speed_m_s: float  # w = ds/dt (signed: the direction of travel along the path parameter)
    tangent: Vec  # unit tangent sigma_s
    sigma_ss: Vec  # 1/m


class TrajectoryTracker:
    """Constant-speed trajectory tracking of ``path`` (the baseline; see the module docstring).

    Same constructor as :class:`~pf_offboard.control.PathFollower`: ``speed`` m/s (its sign picks
    the direction of travel), ``gains`` (the transversal bandwidth / damping is used on every
    axis), ``yaw``, ``limits``, ``projector`` (closest point, for reporting), ``compensator``.
    """

    #: the pipeline passes each sample's time to :meth:`update` and calls :meth:`reset` on activation
    needs_time = True

    def __init__(
        self,
        path: Path,
        speed: float = 1.5,
        *,
        gains: Gains | None = None,
        yaw: YawSpec | None = None,
        limits: Limits | None = None,
        projector: Any = None,
        vehicle: VehicleModel | None = None,
        compensation: Compensation | None = None,
        compensator: InnerLoopCompensator | None = None,
    ) -> None:
        # the follower's validation and building blocks (control law with the limits, yaw profile,
        # projector), so both controllers are built from the same arguments (and defaults) the same way
        base = PathFollower(path, speed, gains=gains, yaw=yaw, limits=limits, projector=projector, vehicle=vehicle,
                            compensation=compensation, compensator=compensator)  # fmt: skip
        self.path, self.speed, self.gains, self.yaw, self.limits = base.path, base.speed, base.gains, base.yaw, base.limits
        self.projector, self.compensator = base.projector, base.compensator
        self.law: ControlLaw = base.law
        self._yaw: YawProfile = base._yaw
        self._closed = bool(path.closed)
        self._length = float(path.length_m)
        self._t0: float | None = None  # time of activation (s) and arclength there (m)
        self._s0 = 0.0

    @classmethod
    def from_config(cls, config: ControllerConfig) -> TrajectoryTracker:
        """Build the path and tracker from a loaded config (``pf_offboard.config.load_config``),
        with the gains, limits, yaw and compensation the path follower gets from it (whatever
        its ``controller`` key says)."""
        return cls.like(PathFollower.from_config(config))

    @classmethod
    def like(cls, follower: PathFollower) -> TrajectoryTracker:
        """The tracker of ``follower``'s path, speed, gains, yaw, limits and compensator (shared)."""
        return cls(
            follower.path, follower.speed, gains=follower.gains, yaw=follower.yaw, limits=follower.limits,
            vehicle=follower.vehicle, compensator=follower.compensator,
            compensation=follower.compensation if follower.compensator is not None else Compensation.off(),
        )  # fmt: skip

    def cap_tilt(self, max_tilt_deg: float) -> None:
        """Fly within ``max_tilt_deg`` when it is below :attr:`limits`' (see PathFollower.cap_tilt)."""
        limits = self.limits.with_tilt_at_most(max_tilt_deg)
        if limits is not self.limits:
            self.limits = limits
            self.law = ControlLaw(self.gains, self.limits)

    def reset(self) -> None:
        """Start the timing over at the next :meth:`update` (activation; an estimator reset, after
        which the old schedule means nothing), forget the warm start and the compensator's state."""
        self._t0 = None
        self.projector.reset()
        if self.compensator is not None:
            self.compensator.reset()

    def hold_heading(self, yaw_rad: float) -> bool:
        """As :meth:`PathFollower.hold_heading`: the heading ``YawSpec.hold`` flies from now on."""
        return self._yaw.hold(yaw_rad)

    @property
    def start(self) -> tuple[float, float] | None:
        """(activation time s, arclength m there) of the running schedule; None before the first update."""
        return None if self._t0 is None else (self._t0, self._s0)

    # ------------------------------------------------------------------ the timed reference
    def _progress(self, tau: float) -> tuple[float, float, float]:
        """(distance m, speed m/s, acceleration m/s^2) travelled along the direction of travel
        ``tau`` s after activation: constant speed; on an open path braking to the end at the
        law's approach deceleration (harder if the start leaves less room)."""
        v = abs(self.speed)
        if tau <= 0.0:
            return 0.0, v, 0.0
        if self._closed:
            return v * tau, v, 0.0
        room = self._length - self._s0 if self.speed > 0.0 else self._s0
        if room <= 0.0:
            return 0.0, 0.0, 0.0
        dec = max(self.law.a_dec, v * v / (2.0 * room))
        t_cruise = (room - v * v / (2.0 * dec)) / v
        if tau <= t_cruise:
            return v * tau, v, 0.0
        h = tau - t_cruise
        if h >= v / dec:
            return room, 0.0, 0.0
        return v * t_cruise + v * h - 0.5 * dec * h * h, v - dec * h, -dec

    def reference(self, time_s: float) -> Reference:
        """The timed reference at ``time_s`` (the schedule must have started: after one update)."""
        if self._t0 is None:
            raise InputError("time_s", "the schedule starts at the first update after reset()")
        d, w, wd = self._progress(time_s - self._t0)
        sign = 1.0 if self.speed > 0.0 else -1.0
        s = self._s0 + sign * d
        w, wd = sign * w, sign * wd
        lam = self.path.lam_at_arclength(s)
        sv = self.path.eval_floats(lam)
        tan, s_ss, s_sss = onpath_derivatives(sv[3:6], sv[6:9], sv[9:12])
        w2, w3 = w * w, w * w * w
        return Reference(
            eta1_m=self.path.arclength(lam),
            lam=lam,
            position_m=(sv[0], sv[1], sv[2]),
            velocity_m_s=(tan[0] * w, tan[1] * w, tan[2] * w),
            accel_m_s2=tuple(s_ss[i] * w2 + tan[i] * wd for i in range(3)),  # type: ignore[arg-type]
            jerk_m_s3=tuple(s_sss[i] * w3 + 3.0 * s_ss[i] * w * wd for i in range(3)),  # type: ignore[arg-type]
            speed_m_s=w,
            tangent=tan,
            sigma_ss=s_ss,
        )

    # ------------------------------------------------------------------ the law
    def _feedback(self, e: Vec, v_ref: Vec, v: Vec) -> tuple[Vec, bool, bool]:
        """(correction m/s^2, reduced by the acceleration bound, approach speed limited): the
        nested PD ``kd (v_d - v)`` with the follower's approach-speed profile and slew shaping."""
        law = self.law
        d = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        speed, limited = law.approach_speed(d) if d > 0.0 else (0.0, False)
        k = speed / d if d > 0.0 else 0.0  # 1/s: desired approach velocity per metre of error
        dv = (v_ref[0] - k * e[0] - v[0], v_ref[1] - k * e[1] - v[1], v_ref[2] - k * e[2] - v[2])
        n_dv = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
        if n_dv == 0.0:
            return (0.0, 0.0, 0.0), False, limited
        n = law.shape(law.kd, law.dv_lin, n_dv)
        reduced = n > law.u_max
        if reduced:
            n = law.u_max
        c = n / n_dv
        return (dv[0] * c, dv[1] * c, dv[2] * c), reduced, limited

    def _allocate(self, a_ref: Vec, u: Vec) -> tuple[Vec, bool]:
        """``a_ref + mu u`` with the largest mu in [0, 1] that keeps the thrust vector feasible
        (the feed-forward has priority); a_ref itself infeasible: the clipped sum."""
        ts = self.law.thrust_set
        f_ref = (a_ref[0], a_ref[1], a_ref[2] + G)
        iv = ts.line_interval(f_ref, u) if (u[0] or u[1] or u[2]) else (0.0, 0.0)
        if iv is None or not iv[0] <= 0.0 <= iv[1]:
            f = ts.clip((f_ref[0] + u[0], f_ref[1] + u[1], f_ref[2] + u[2]))
            return (f[0], f[1], f[2] - G), True
        mu = 1.0 if iv[1] >= 1.0 else iv[1]
        return (a_ref[0] + mu * u[0], a_ref[1] + mu * u[1], a_ref[2] + mu * u[2]), mu < 1.0

    def update(self, position: ArrayLike, velocity: ArrayLike, time_s: float | None = None) -> Command:
        """One control step at position (m), velocity (m/s), world ENU, sampled at ``time_s`` (s,
        any monotonic clock; required: the reference is timed). The first step after
        :meth:`reset` starts the schedule at the closest point of the path.

        Raises :class:`InputError` for non-finite input or a missing time.
        """
        y = _vec(position, "position", MAX_POSITION_ABS_M)
        v = _vec(velocity, "velocity", MAX_VELOCITY_ABS_M_S)
        if time_s is None:
            raise InputError("time_s", "the trajectory tracker is time-varying: pass each sample's time (s)")
        t_s = float(time_s)
        if not math.isfinite(t_s):
            raise InputError("time_s", f"must be finite, got {time_s!r}")
        lam = float(self.projector.update(y))
        if self._t0 is None:
            self._t0, self._s0 = t_s, self.path.arclength(lam)
        comp = self.compensator
        y_law, v_law, t_law = y, v, t_s
        if comp is not None:
            y_law, v_law = comp.predict(t_s, y, v)
            if _finite(y_law, v_law):
                t_law = t_s + comp.horizon_s  # the state predicted to when this setpoint acts
            else:
                comp.reset()
                y_law, v_law = y, v
        ref = self.reference(t_law)
        p_r, v_r = ref.position_m, ref.velocity_m_s
        e = (y_law[0] - p_r[0], y_law[1] - p_r[1], y_law[2] - p_r[2])
        b = (0.0, 0.0, 0.0)
        if comp is not None:
            # integral action as reference offsets, as in the follower: along the reference's
            # tangent (speed) and normals (position)
            b_speed, b_n2, b_n3 = comp.integral_offsets()
            (_, _, _), (e2, _, _), (e3, _, _) = self.path.frame_jets(ref.lam)
            v_r = tuple(v_r[i] + b_speed * ref.tangent[i] for i in range(3))  # type: ignore[assignment]
            b = tuple(b_n2 * e2[i] + b_n3 * e3[i] for i in range(3))  # type: ignore[assignment]
            e = (e[0] + b[0], e[1] + b[1], e[2] + b[2])
        u, reduced, limited = self._feedback(e, v_r, v_law)
        (ax, ay, az), scaled = self._allocate(ref.accel_m_s2, u)
        jerk = ref.jerk_m_s3
        if comp is not None:
            # as in the path follower: the lag lead replaces the roll/pitch rate feed-forward
            # the drag inverted at the reference velocity, the deviation's share bounded, and no
            # push beyond the reference speed (InnerLoopCompensator.invert): inverted at the
            # velocity, a drag above the vehicle's is positive velocity feedback (a runaway)
            sp = comp.invert(t_s, comp.lead((ax, ay, az), jerk), v_law, v_r)
            ax, ay, az = comp.commit(t_s, sp, self.law.thrust_set.clip)
        f = (ax, ay, az + G)
        thrust = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        tilt, thrust_sat = self.law.thrust_set.active(f)
        psi, dpsi = self._yaw.evaluate(ref.eta1_m, ref.tangent, ref.sigma_ss)
        yaw_rate = dpsi * ref.speed_m_s
        axes = attitude_from_thrust(f, psi)
        q = quaternion_from_axes(*axes)
        omega = body_rates(axes, thrust, (0.0, 0.0, 0.0) if comp is not None else jerk, yaw_rate)
        if not _finite((ax, ay, az), q, omega, (thrust, psi, yaw_rate)):
            raise InputError("state", f"no finite command at position {list(y)}, velocity {list(v)}")
        # report the measured state at the closest point, as the follower does
        sm = self.path.eval_floats(lam)
        dist = math.sqrt((y[0] - sm[0]) ** 2 + (y[1] - sm[1]) ** 2 + (y[2] - sm[2]) ** 2)
        st = evaluate_terms(self.path, lam, y, v).state
        if comp is not None:
            # measured tracking errors at the measurement's time, in the reference's frame
            now = self.reference(t_s)
            (_, _, _), (e2, _, _), (e3, _, _) = self.path.frame_jets(now.lam)
            em = (y[0] - now.position_m[0], y[1] - now.position_m[1], y[2] - now.position_m[2])
            tn = now.tangent
            speed_err = now.speed_m_s - (tn[0] * v[0] + tn[1] * v[1] + tn[2] * v[2])
            free = not (reduced or scaled or tilt or thrust_sat or limited)
            comp.integrate(
                t_s,
                speed_err,
                e2[0] * em[0] + e2[1] * em[1] + e2[2] * em[2],
                e3[0] * em[0] + e3[1] * em[1] + e3[2] * em[2],
                free,
            )
            comp.watch(t_s, math.sqrt(em[0] * em[0] + em[1] * em[1] + em[2] * em[2]), speed_err)  # the rollback guard
        return Command(
            acceleration=np.array((ax, ay, az)),
            thrust=thrust,
            attitude=np.array(q),
            body_rates=np.array(omega),
            yaw=wrap_pi(psi),
            yaw_rate=yaw_rate,
            state=st,
            lam=lam,
            cross_track_m=dist,
            saturation=Saturation(False, reduced or scaled, tilt, thrust_sat, limited),
        )
