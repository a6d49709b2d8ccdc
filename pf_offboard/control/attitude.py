"""Attitude → body-rate law for ``rates`` output: the paper's Fig. 1 cascade closed by the caller.

A rates-mode user (the app's ``rates`` output, or anyone driving another simulator's body-rate
controller) turns the core's commanded attitude ``q_des`` and its feed-forward ``ω_ff`` into
body-rate setpoints with :class:`AttitudeRateLaw`. Pure: no state, no clock, no I/O.

Frames: world ENU, body FLU; quaternions (w, x, y, z) body → world; rates in body FLU, rad/s.

The law (tilt-prioritised reduced attitude control)::

    q_e   = q_meas⁻¹ ⊗ q_des                  attitude error, body frame
    q_tilt: the shortest rotation taking the measured body z onto the desired one (no z part)
    q_yaw = q_tilt⁻¹ ⊗ q_e                    the remaining rotation about body z
    ω_fb  = (2/τ) · q_tilt,xyz  +  (2/τ_yaw) · sign(q_yaw,w) · q_yaw,z · e_z
    ω     = ω_ff + s_xy · ω_fb,xy  (+ the same for z with s_z)

For small errors this is a first-order decay of the tilt error with time constant ``τ`` and of the
heading error with ``τ_yaw``. ``ω_ff`` is the command's ``body_rates``: the paper's feed-forward
without the inner-loop compensator; with it only the yaw rate (the compensator's lag lead already
puts the setpoint ahead of the path's motion, and a roll/pitch feed-forward on top would lead
twice). The roll/pitch part of ``ω`` is bounded by
``max_roll_pitch_rate_rad_s`` (Euclidean norm) and the yaw part by ``max_yaw_rate_rad_s``: the
feedback is scaled by the largest ``s ∈ [0, 1]`` that keeps the total inside its bound, so its
direction is kept; only a feed-forward that alone exceeds a bound is itself scaled down to it.
Separating yaw means a large heading error (say 180° after a take-off at another heading) turns
the vehicle at ``max_yaw_rate_rad_s`` instead of asking for tens of rad/s, and never competes
with the tilt that holds the vehicle on the path.

**Why the time constant matters.** This loop sits on top of the autopilot's own body-rate loop
(closed-loop time constant ``τ_r``, plus transport delay). An outer loop is only stable with
margin when it is several times slower than the loop it drives: with ``τ = 0.05 s`` (crossover
20 rad/s) over a real PX4 rate loop (measured on PX4 SIH: τ_r ≈ 0.045 s plus ≈ 0.045 s of delay)
the phase margin is gone and the vehicle tumbles; ``τ = 0.2–0.25 s`` flew on PX4 and ArduPilot.
The default, :data:`DEFAULT_ATTITUDE_TIME_CONSTANT_S`, is 0.25 s; with an identified rate loop
use :meth:`AttitudeRateLaw.for_rate_loop` (``τ = 4·τ_r``, at least
:data:`MIN_ATTITUDE_TIME_CONSTANT_S`).

The default ``rates`` output, :meth:`AttitudeTracker.from_vehicle`, is this law plus an attitude
reference with the compensator's modelled lag, engaged only over a rate loop it identifies in
flight as fast and free of dead time (:class:`RateLoopIdentifier`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from pf_offboard.errors import InputError

DEFAULT_ATTITUDE_TIME_CONSTANT_S = 0.25
"""Default τ (s): about 4× a typical autopilot's closed rate loop plus delay (PX4 SIH ≈ 0.045 s lag
+ 0.045 s delay); flew on PX4 SITL at 0.2 s and on ArduCopter SITL at 0.25 s."""
MIN_ATTITUDE_TIME_CONSTANT_S = 0.05
"""Smallest τ (s) :meth:`AttitudeRateLaw.for_rate_loop` derives (an ideal, fast inner loop)."""
RATE_LOOP_SEPARATION = 4.0
"""τ / τ_rate used by :meth:`AttitudeRateLaw.for_rate_loop` (time-scale separation of the cascade)."""
DEFAULT_MAX_ROLL_PITCH_RATE_RAD_S = 3.5  # ≈ 200 °/s, below PX4's MC_ROLLRATE_MAX (220 °/s)
DEFAULT_MAX_YAW_RATE_RAD_S = 2.0  # ≈ 115 °/s, below PX4's MC_YAWRATE_MAX (200 °/s)
YAW_TIME_CONSTANT_FACTOR = 2.0
"""τ_yaw / τ when ``yaw_time_constant_s`` is not given (yaw rate loops are slower: PX4 SIH ≈ 0.3 s)."""


def _positive(name: str, value: float, lo: float, hi: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise InputError(name, f"must be in [{lo:g}, {hi:g}], got {value!r}")
    return v


def _quat4(name: str, q: ArrayLike) -> tuple[float, float, float, float]:
    a = np.asarray(q, dtype=float).reshape(-1)
    if a.shape != (4,) or not all(map(math.isfinite, a.tolist())):
        raise ValueError(f"{name}: need a finite (w, x, y, z) quaternion, got {q!r}")
    n = math.sqrt(float(a @ a))
    if n < 1e-9:
        raise ValueError(f"{name}: zero quaternion")
    return (a[0] / n, a[1] / n, a[2] / n, a[3] / n)


def _scale_into_ball(ff: tuple[float, ...], fb: tuple[float, ...], bound: float) -> tuple[float, float]:
    """(factor on ff, factor on fb) so that |f·ff + s·fb| <= bound with s in [0, 1] as large as
    possible; ff is scaled down (s = 0) only when it alone exceeds the bound."""
    ff2 = sum(v * v for v in ff)
    if ff2 >= bound * bound:
        return (bound / math.sqrt(ff2) if ff2 > 0.0 else 1.0), 0.0
    fb2 = sum(v * v for v in fb)
    total2 = sum((a + b) ** 2 for a, b in zip(ff, fb, strict=True))
    if total2 <= bound * bound or fb2 == 0.0:
        return 1.0, 1.0
    fd = sum(a * b for a, b in zip(ff, fb, strict=True))
    s = (-fd + math.sqrt(fd * fd + fb2 * (bound * bound - ff2))) / fb2
    return 1.0, min(1.0, max(0.0, s))


@dataclass(frozen=True)
class AttitudeRates:
    """One output of :meth:`AttitudeRateLaw.evaluate`. Body FLU, rad/s."""

    rates_flu_rad_s: NDArray[np.float64]  # (3,) the command: ω_ff + scaled feedback
    feedback_flu_rad_s: NDArray[np.float64]  # (3,) the unsaturated feedback ω_fb
    tilt_error_rad: float  # angle between the measured and the desired body z
    yaw_error_rad: float  # remaining rotation about body z, in (-π, π]
    saturated: bool  # a bound reduced the feedback (or the feed-forward)


@dataclass(frozen=True)
class AttitudeRateLaw:
    """Bounded tilt-prioritised attitude controller: attitude error → body-rate command.

    ``time_constant_s``: τ of the tilt error decay (s); ``yaw_time_constant_s``: τ of the heading
    error decay (s; None: ``2·τ``); ``max_roll_pitch_rate_rad_s``: bound on the norm of the
    commanded roll/pitch rates (rad/s); ``max_yaw_rate_rad_s``: bound on the commanded yaw rate
    (rad/s). See the module docstring for the law and the choice of τ.

        law = AttitudeRateLaw()                                  # τ = 0.25 s
        law = AttitudeRateLaw.for_rate_loop(0.05)                # identified rate loop: τ = 0.2 s
        rates_flu = law.update(cmd.attitude, q_meas_enu_flu, cmd.body_rates)
    """

    time_constant_s: float = DEFAULT_ATTITUDE_TIME_CONSTANT_S
    max_roll_pitch_rate_rad_s: float = DEFAULT_MAX_ROLL_PITCH_RATE_RAD_S
    max_yaw_rate_rad_s: float = DEFAULT_MAX_YAW_RATE_RAD_S
    yaw_time_constant_s: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_constant_s", _positive("attitude.time_constant_s", self.time_constant_s, 0.01, 2.0))
        object.__setattr__(
            self, "max_roll_pitch_rate_rad_s",
            _positive("attitude.max_roll_pitch_rate_rad_s", self.max_roll_pitch_rate_rad_s, 0.1, 50.0),
        )  # fmt: skip
        object.__setattr__(
            self, "max_yaw_rate_rad_s", _positive("attitude.max_yaw_rate_rad_s", self.max_yaw_rate_rad_s, 0.05, 50.0)
        )
        if self.yaw_time_constant_s is not None:
            object.__setattr__(
                self, "yaw_time_constant_s", _positive("attitude.yaw_time_constant_s", self.yaw_time_constant_s, 0.01, 5.0)
            )

    @property
    def yaw_time_constant_effective_s(self) -> float:
        """τ_yaw actually used (s)."""
        return self.yaw_time_constant_s if self.yaw_time_constant_s is not None else YAW_TIME_CONSTANT_FACTOR * self.time_constant_s

    @classmethod
    def for_rate_loop(cls, rate_time_constant_s: float, **kwargs: Any) -> AttitudeRateLaw:
        """The law for an autopilot whose closed body-rate loop has time constant
        ``rate_time_constant_s`` (s; lag plus delay, e.g. ``VehicleModel.rate_time_constant_s``):
        ``τ = 4·τ_rate``, at least :data:`MIN_ATTITUDE_TIME_CONSTANT_S`. ``0`` (unknown) gives
        the default τ. Other fields as keywords."""
        tau_r = float(rate_time_constant_s)
        if not (math.isfinite(tau_r) and 0.0 <= tau_r <= 1.0):
            raise InputError("vehicle.rate_time_constant_s", f"must be in [0, 1] s, got {rate_time_constant_s!r}")
        tau = DEFAULT_ATTITUDE_TIME_CONSTANT_S if tau_r == 0.0 else max(MIN_ATTITUDE_TIME_CONSTANT_S, RATE_LOOP_SEPARATION * tau_r)
        return cls(time_constant_s=min(tau, 2.0), **kwargs)

    @classmethod
    def from_vehicle(cls, vehicle: Any, **kwargs: Any) -> AttitudeRateLaw:
        """:meth:`for_rate_loop` with ``vehicle.rate_time_constant_s`` (a
        :class:`pf_offboard.control.VehicleModel`; 0 = unknown → the default τ)."""
        return cls.for_rate_loop(getattr(vehicle, "rate_time_constant_s", 0.0), **kwargs)

    def evaluate(self, q_des_enu_flu: ArrayLike, q_meas_enu_flu: ArrayLike, rates_ff_flu_rad_s: ArrayLike) -> AttitudeRates:
        """The full output (command, unsaturated feedback, errors, saturation) for one sample.

        Raises ValueError for a non-finite or zero quaternion or non-finite feed-forward.
        """
        dw, dx, dy, dz = _quat4("q_des_enu_flu", q_des_enu_flu)
        mw, mx, my, mz = _quat4("q_meas_enu_flu", q_meas_enu_flu)
        ff_a = np.asarray(rates_ff_flu_rad_s, dtype=float).reshape(-1)
        if ff_a.shape != (3,) or not np.all(np.isfinite(ff_a)):
            raise ValueError(f"rates_ff_flu_rad_s: need 3 finite values, got {rates_ff_flu_rad_s!r}")
        ffx, ffy, ffz = float(ff_a[0]), float(ff_a[1]), float(ff_a[2])
        # q_e = q_meas^-1 ⊗ q_des (body frame error), shortest way round
        ew = mw * dw + mx * dx + my * dy + mz * dz
        ex = mw * dx - mx * dw - my * dz + mz * dy
        ey = mw * dy + mx * dz - my * dw - mz * dx
        ez = mw * dz - mx * dy + my * dx - mz * dw
        if ew < 0.0:
            ew, ex, ey, ez = -ew, -ex, -ey, -ez
        # desired body z in the measured body frame: third column of R(q_e)
        zx = 2.0 * (ex * ez + ew * ey)
        zy = 2.0 * (ey * ez - ew * ex)
        zz = 1.0 - 2.0 * (ex * ex + ey * ey)
        # q_tilt ∝ (1 + e_z·z_d, e_z × z_d) = (1 + zz, -zy, zx, 0)
        tw, tx, ty = 1.0 + zz, -zy, zx
        n = math.sqrt(tw * tw + tx * tx + ty * ty)
        if n < 1e-9:  # upside down relative to the demand: tilt about body x
            tw, tx, ty = 0.0, 1.0, 0.0
        else:
            tw, tx, ty = tw / n, tx / n, ty / n
        # q_yaw = q_tilt^-1 ⊗ q_e: a rotation about z (its x, y parts vanish)
        yw = tw * ew + tx * ex + ty * ey
        yz = tw * ez - tx * ey + ty * ex
        if yw < 0.0:
            yw, yz = -yw, -yz
        k = 2.0 / self.time_constant_s
        k_yaw = 2.0 / self.yaw_time_constant_effective_s
        fbx, fby, fbz = k * tx, k * ty, k_yaw * yz
        cff, s_xy = _scale_into_ball((ffx, ffy), (fbx, fby), self.max_roll_pitch_rate_rad_s)
        cffz, s_z = _scale_into_ball((ffz,), (fbz,), self.max_yaw_rate_rad_s)
        rates = np.array([cff * ffx + s_xy * fbx, cff * ffy + s_xy * fby, cffz * ffz + s_z * fbz])
        saturated = cff < 1.0 or s_xy < 1.0 or cffz < 1.0 or s_z < 1.0
        return AttitudeRates(
            rates_flu_rad_s=rates,
            feedback_flu_rad_s=np.array([fbx, fby, fbz]),
            tilt_error_rad=2.0 * math.atan2(math.hypot(tx, ty), tw),
            yaw_error_rad=2.0 * math.atan2(yz, yw),
            saturated=saturated,
        )

    def update(self, q_des_enu_flu: ArrayLike, q_meas_enu_flu: ArrayLike, rates_ff_flu_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Body-rate command (body FLU, rad/s) for a desired and a measured attitude (body FLU →
        world ENU) and the feed-forward body rates ω_ff (body FLU, rad/s)."""
        return self.evaluate(q_des_enu_flu, q_meas_enu_flu, rates_ff_flu_rad_s).rates_flu_rad_s


REFERENCE_LAG_FRACTION = 0.75
"""The attitude reference's lag / the vehicle model's ``accel_lag_xy_s`` (:meth:`AttitudeTracker.from_vehicle`):
the autopilot's own rate loop adds the rest (rotorpy, 33 ms rate loop: 0.06-0.085 s of
reference lag flew 0.26-0.29 cm against the model's 0.1 s; 0.1 s itself 0.35 cm, 0.04 s 4 cm in wind)."""
MAX_REFERENCE_GAP_S = 0.25
"""A gap between samples longer than this (s) restarts the reference at the measured attitude."""


def _quat_mul(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)  # fmt: skip


class AttitudeTracker:
    """The default ``rates`` output (:meth:`from_vehicle`; the app's too): the law, and over a rate
    loop identified fast an attitude reference whose response is the lag the follower's
    compensator models.

    :class:`AttitudeRateLaw` alone makes the tilt follow the demand as a first-order lag of its
    ``τ`` (0.25 s: it must stay slow over a real autopilot's rate loop), while the follower's
    :class:`~pf_offboard.control.compensator.InnerLoopCompensator` predicts, leads and inverts a
    lag of ``accel_lag_xy_s`` (0.1 s typical), and its identifier varies the dead time, gain and
    drag but not the lag: in rotorpy (33 ms rate loop) the law alone flew the figure-eight at
    1.4 cm, identified or not.
    The reference separates the two: an attitude reference ``q_r`` follows the demand with lag
    ``reference_lag_s`` (the same law with that τ, integrated here: no measurement, so no loop
    to destabilise), its rate is the feed-forward, and the law's feedback (τ) only pulls the
    vehicle onto the reference. In rotorpy the follower's identification then adopts the dead time:
    0.27 cm (0.44 cm in a 3 m/s wind), as the acceleration output does.

    **Only over a fast rate loop without dead time.** Where the rate loop had dead time the
    reference's faster tilt hurt: the independent simulator of tests/control/test_independent_quad.py
    (30 ms + 20 ms latency) oscillated up to the rate bound once the follower adopted a 0-0.04 s dead
    time (9 cm; 1.7 cm with the identification off, 0.9 cm with the law alone); the mock's px4-sih
    preset (80 ms dead time) had its 1.2-1.8 Hz ripple of the commanded acceleration tripled with no
    adoption at all (3-6 cm, 16-20 cm/s against 1.4-3.3 cm, 3-14 cm/s); real ArduCopter SITL, whose
    rates go through its own attitude target, flew 2.5-3.0 cm, 8.7-10.2 cm/s against 2.3 cm, 4.6 cm/s
    (docs/design-decisions.md). So with ``identify_rate_loop`` (the :meth:`from_vehicle` default)
    it flies the law alone, identifies the rate loop (:class:`RateLoopIdentifier`, from the
    measured attitudes and the rates it sent) and engages the reference only once that loop's lag +
    dead time is at most :data:`FAST_RATE_LOOP_S` with a dead time of at most
    :data:`FAST_RATE_LOOP_MAX_DELAY_S` (rotorpy after about 1 s); it drops it for good (until
    :meth:`reset`) when the response then exceeds :data:`SLOW_RATE_LOOP_S` (real ArduCopter, whose
    rates answered the law's commands in 30-40 ms and the reference's in 60-70 ms, switched back
    and forth otherwise). Disengaged, its output is the law's, bit for bit.
    Body FLU, world ENU, rad/s, quaternions (w, x, y, z).

    ``reference_lag_s`` None: the law alone (stateless). Stateful: call :meth:`update` once per
    control step with the sample's time; :meth:`reset` at activation or after another setpoint.

        tracker = AttitudeTracker.from_vehicle(VehicleModel.typical())   # τ 0.25 s, reference 0.075 s when fast
        rates_flu = tracker.update(cmd.attitude, q_meas_enu_flu, cmd.body_rates, time_s=t)
    """

    def __init__(self, law: AttitudeRateLaw | None = None, reference_lag_s: float | None = None,
                 identify_rate_loop: bool = False) -> None:  # fmt: skip
        self.law = law if law is not None else AttitudeRateLaw()
        self.reference_lag_s = (None if reference_lag_s is None
                                else _positive("attitude.reference_lag_s", reference_lag_s, 0.01, 2.0))  # fmt: skip
        self._ref = None if self.reference_lag_s is None else AttitudeRateLaw(
            time_constant_s=self.reference_lag_s, yaw_time_constant_s=self.law.yaw_time_constant_effective_s,
            max_roll_pitch_rate_rad_s=self.law.max_roll_pitch_rate_rad_s, max_yaw_rate_rad_s=self.law.max_yaw_rate_rad_s,
        )  # fmt: skip
        # identify_rate_loop: the reference only while the vehicle's rate loop is identified fast
        self.rate_loop = RateLoopIdentifier() if identify_rate_loop and self._ref is not None else None
        self.reset()

    @classmethod
    def from_vehicle(cls, vehicle: Any, identify_rate_loop: bool = True, **kwargs: Any) -> AttitudeTracker:
        """The default ``rates`` output: the feedback law :meth:`AttitudeRateLaw.from_vehicle` (τ
        from the rate loop) and a reference lag of :data:`REFERENCE_LAG_FRACTION` ×
        ``vehicle.accel_lag_xy_s`` (none for a model without a lag: the paper's ideal loop), used
        only while the vehicle's rate loop is identified fast (``identify_rate_loop``, the default;
        False: always)."""
        lag = float(getattr(vehicle, "accel_lag_xy_s", 0.0) or 0.0)
        law = AttitudeRateLaw.from_vehicle(vehicle, **kwargs)
        return cls(law, REFERENCE_LAG_FRACTION * lag if lag > 0.0 else None, identify_rate_loop=identify_rate_loop)

    @property
    def reference_engaged(self) -> bool:
        """True while the attitude reference shapes the command (False: the law alone)."""
        return self._ref is not None and (self.rate_loop is None or self._engaged)

    def reset(self) -> None:
        """Forget the reference (it restarts at the next measured attitude) and the rate loop's
        identification."""
        self.reference_enu_flu: tuple[float, float, float, float] | None = None
        self._t: float | None = None
        self._w_ref = (0.0, 0.0, 0.0)
        self._engaged = False
        self._dropped = False
        if self.rate_loop is not None:
            self.rate_loop.reset()

    def _engage(self) -> None:
        """Follow the identification (with hysteresis): engage at a response (lag + dead time) of at
        most :data:`FAST_RATE_LOOP_S` with a dead time of at most :data:`FAST_RATE_LOOP_MAX_DELAY_S`,
        disengage above :data:`SLOW_RATE_LOOP_S` for the rest of the flight (until :meth:`reset`)."""
        r = self.rate_loop.response_s if self.rate_loop is not None else None
        if r is None or self.rate_loop is None or self.rate_loop.best is None:
            return
        if (not self._engaged and not self._dropped and r <= FAST_RATE_LOOP_S
                and self.rate_loop.best[1] <= FAST_RATE_LOOP_MAX_DELAY_S):  # fmt: skip
            self._engaged = True
            self.reference_enu_flu = None  # restart the reference at the measured attitude
        elif self._engaged and r > SLOW_RATE_LOOP_S:
            # dropped for good (until reset): a loop that answers the reference's faster rates
            # slower than the law's would otherwise switch back and forth (real ArduCopter did)
            self._engaged = False
            self._dropped = True

    def update(self, q_des_enu_flu: ArrayLike, q_meas_enu_flu: ArrayLike, rates_ff_flu_rad_s: ArrayLike,
               time_s: float) -> NDArray[np.float64]:  # fmt: skip
        """Body-rate command (body FLU, rad/s) at ``time_s`` (s, monotonic) for a desired and a
        measured attitude and the demand's feed-forward rates. Raises ValueError for non-finite
        input (as :meth:`AttitudeRateLaw.evaluate`)."""
        if self._ref is None:
            return self.law.update(q_des_enu_flu, q_meas_enu_flu, rates_ff_flu_rad_s)
        t = float(time_s)
        if not math.isfinite(t):
            raise ValueError(f"time_s: must be finite, got {time_s!r}")
        q_meas = _quat4("q_meas_enu_flu", q_meas_enu_flu)
        if self.rate_loop is not None:
            self._engage()
            if not self._engaged:
                out = self.law.update(q_des_enu_flu, q_meas_enu_flu, rates_ff_flu_rad_s)  # as the law alone
                self.rate_loop.update(t, q_meas, out)
                self.reference_enu_flu, self._t = None, t
                return out
        q_r = self.reference_enu_flu
        if q_r is None or self._t is None or t - self._t > MAX_REFERENCE_GAP_S or t < self._t:
            q_r = q_meas
        elif t > self._t:  # advance the reference with the rate it was given
            dt = t - self._t
            wx, wy, wz = (w * dt for w in self._w_ref)
            th = math.sqrt(wx * wx + wy * wy + wz * wz)
            k = math.sin(0.5 * th) / th if th > 1e-12 else 0.5
            q_r = _quat_mul(q_r, (math.cos(0.5 * th), k * wx, k * wy, k * wz))
            n = math.sqrt(sum(c * c for c in q_r))
            q_r = (q_r[0] / n, q_r[1] / n, q_r[2] / n, q_r[3] / n)
        w_ref = self._ref.update(q_des_enu_flu, q_r, rates_ff_flu_rad_s)
        self.reference_enu_flu, self._t = q_r, t
        self._w_ref = (float(w_ref[0]), float(w_ref[1]), float(w_ref[2]))
        out = self.law.update(q_r, q_meas, w_ref)
        if self.rate_loop is not None:
            self.rate_loop.update(t, q_meas, out)
        return out


RATE_LOOP_LAGS_S = (0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.1, 0.15)
"""Candidate time constants (s) of the autopilot's closed body-rate loop (:class:`RateLoopIdentifier`)."""
RATE_LOOP_DELAYS_S = (0.0, 0.01, 0.02, 0.03, 0.04, 0.06, 0.08)
"""Candidate dead times (s) between a rate command and the rate loop's response."""
FAST_RATE_LOOP_S = 0.04
"""A rate loop whose identified lag + dead time is at most this (s) is fast enough for the
attitude reference (:class:`AttitudeTracker`): rotorpy's (33 ms, no dead time) is, the independent
simulator's (30 ms + 20 ms latency) and the autopilots' (PX4 SIH ≈ 45 + 45 ms) are not."""
FAST_RATE_LOOP_MAX_DELAY_S = 0.01
"""… and whose identified dead time is at most this (s): dead time is what the reference's faster
tilt cannot stand (the independent simulator's 20 ms latency, SIH's 80 ms)."""
SLOW_RATE_LOOP_S = 0.06
"""An engaged reference is dropped again when the identified response exceeds this (s)."""
RATE_LOOP_MEMORY_S = 3.0
"""Time constant (s) of the identifier's exponential forgetting."""
RATE_LOOP_MIN_EXCITATION_RAD2_S = 0.1
"""The identifier decides once the (forgotten) sum of squared measured roll/pitch rates times
the sample interval reaches this (rad²/s): about a second at 0.3 rad/s."""
RATE_LOOP_MAX_RESIDUAL = 0.1
"""… and the best candidate explains the measured rates to within this fraction of their energy."""


class RateLoopIdentifier:
    """Which first-order lag + dead time best maps the roll/pitch rates commanded onto the rates
    measured (from consecutive attitudes), among :data:`RATE_LOOP_LAGS_S` × :data:`RATE_LOOP_DELAYS_S`.

    Call :meth:`update` once per control step with the sample's time, the measured attitude and the
    rate command sent at that step (body FLU rad/s). :attr:`response_s` is the best candidate's lag
    + dead time once the flight excited it enough and the fit is good (else None). Pure Python and
    numpy, deterministic; no clock.
    """

    def __init__(self) -> None:
        lags, delays = np.meshgrid(np.array(RATE_LOOP_LAGS_S), np.array(RATE_LOOP_DELAYS_S), indexing="ij")
        self._lag = lags.reshape(-1)
        self._delay = delays.reshape(-1)
        self.reset()

    def reset(self) -> None:
        """Forget everything (activation, a gap)."""
        n = self._lag.size
        self._state = np.zeros((n, 2))  # each candidate's predicted rate at the last sample
        self._sse = np.zeros(n)
        self._energy = 0.0
        self._q: tuple[float, float, float, float] | None = None
        self._t: float | None = None
        self._cmds: list[tuple[float, float, float]] = []  # (time sent, roll rate, pitch rate)
        self.response_s: float | None = None
        self.best: tuple[float, float] | None = None  # (lag s, dead time s)

    def _command_at(self, t: float) -> tuple[float, float]:
        for tk, x, y in reversed(self._cmds):
            if tk <= t + 1e-9:
                return x, y
        return 0.0, 0.0

    def update(self, time_s: float, q_meas_enu_flu: tuple[float, float, float, float], rates_sent_flu_rad_s: ArrayLike) -> None:
        """One control step: the sample's time (s), the measured attitude (unit (w, x, y, z), body
        FLU → world ENU) and the rates sent at this step (body FLU, rad/s). A gap longer than
        :data:`MAX_REFERENCE_GAP_S` (or time going back) starts over."""
        t = float(time_s)
        q = q_meas_enu_flu
        if self._t is not None and (t - self._t > MAX_REFERENCE_GAP_S or t < self._t):
            self.reset()
        if self._t is not None and self._q is not None and t > self._t:
            h = t - self._t
            # mean measured body rate over the interval: 2 vec(q_prev^-1 ⊗ q) / h
            pw, px, py, pz = self._q
            rw, rx, ry, _ = _quat_mul((pw, -px, -py, -pz), q)
            s = 2.0 / h if rw >= 0.0 else -2.0 / h
            mx, my = s * rx, s * ry
            mid = 0.5 * (t + self._t)
            u = np.empty((self._lag.size, 2))
            for d in RATE_LOOP_DELAYS_S:
                u[self._delay == d] = self._command_at(mid - d)
            a = np.exp(-h / self._lag)
            mean = u + (self._state - u) * ((1.0 - a) * self._lag / h)[:, None]
            self._state = u + (self._state - u) * a[:, None]
            forget = math.exp(-h / RATE_LOOP_MEMORY_S)
            err = mean - np.array([mx, my])
            self._sse = forget * self._sse + h * np.einsum("ij,ij->i", err, err)
            self._energy = forget * self._energy + h * (mx * mx + my * my)
            k = int(np.argmin(self._sse))
            self.best = (float(self._lag[k]), float(self._delay[k]))
            good = self._energy >= RATE_LOOP_MIN_EXCITATION_RAD2_S and self._sse[k] <= RATE_LOOP_MAX_RESIDUAL * self._energy
            self.response_s = self.best[0] + self.best[1] if good else None
        r = np.asarray(rates_sent_flu_rad_s, dtype=float).reshape(-1)
        self._cmds.append((t, float(r[0]), float(r[1])))
        horizon = t - max(RATE_LOOP_DELAYS_S) - 0.05
        while len(self._cmds) > 2 and self._cmds[1][0] <= horizon:
            self._cmds.pop(0)
        self._q, self._t = q, t
