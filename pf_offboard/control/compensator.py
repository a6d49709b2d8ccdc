"""Inner-loop compensation: delay predictor, drag/gain inversion and a disturbance observer.

The paper assumes the cascade below the path follower is an ideal double integrator. A real
autopilot is not: PX4 SIH answers an acceleration setpoint after about 0.24 s (delay + lag), with a
horizontal gain below one and 1 s⁻¹ of linear drag, so a 1.5 Hz loop on top of it oscillates and
flies 10–15 % slow. This module makes the plant seen by the control law a double integrator
again, with the identified :class:`~pf_offboard.control.types.VehicleModel`:

``dv/dt = gain ⊙ lag(a_sp(t − delay)) − drag ⊙ v + d`` (per axis group; delays ``accel_delay_s``
for x/y and ``accel_delay_z_s`` for z, first-order lags ``accel_lag_*_s``). When the two delays
differ, the faster group's setpoints are held back by the difference before they are sent, so every
axis acts ``horizon_s`` (the longer delay) after the law computed it.

Per control step, world frame ENU (m, m/s, m/s²):

1. **Observer** (a linear extended-state observer, poles at ``-observer_rad_s``): estimates ``d``,
   what the model does not explain — wind, a wrong hover thrust, battery sag, drag the model
   misses — from the measured velocity and the setpoints actually sent. It sees the clipped
   setpoint, so saturation cannot wind it up; ``d`` is also bounded by ``max_disturbance_m_s2``.
2. **Predictor** (Smith): integrates the model (lag filter included) over the setpoints already
   computed to the state at ``t + horizon_s`` — when the next setpoint starts to act, on every axis
   at once (the law needs the state at one instant). The control law runs
   on it; the lag stays part of the plant (the follower leads it with the on-path jerk).
3. **Inversion**: the law's acceleration ``a`` becomes ``a_sp = (a + drag ⊙ v̂ − d̂) / gain``,
   after the lag is led along the path (:meth:`InnerLoopCompensator.lead`, which replaces the
   roll/pitch body-rate feed-forward). ``v̂`` there is the on-path reference velocity plus the
   predicted velocity's deviation from it, the deviation's drag bounded per axis to
   ``MAX_DRAG_FEEDBACK_M_S2`` (drag inverted at the velocity is positive velocity feedback).

With ``d̂ = d`` the loop is the nominal one, so the path stays invariant; the observer adds no
explicit time dependence (its state is driven by the measurements only). ``reset()`` forgets
everything (activation, estimator reset, a gap in the telemetry).
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from pf_offboard.control.adaptive import DELAYS_S, LAGS_S, IdentifiedModel, ResponseIdentifier
from pf_offboard.control.types import GRAVITY_M_S2, Compensation, VehicleModel
from pf_offboard.errors import InputError

Vec = tuple[float, float, float]
_ZERO: Vec = (0.0, 0.0, 0.0)

# A telemetry gap longer than this (s) makes the observer and predictor start over: integrating the
# model across it would extrapolate commands the vehicle may not have flown.
MAX_GAP_S = 0.25
# The offset integrators run only this close to the path (m, cross-track): they are meant for the
# steady offsets of a long turn (a few cm). Integrating the approach from metres away (inside the
# exact tube, nothing saturated) wound them up to their bound, and the vehicle then overshot the
# path by ~10 cm and crept back at the integral's 1 rad/s: on the px4-sih mock's fast off-path
# starts that bump alone kept the cross-track above 10 cm for 0.5-1 s after arriving.
OFFSET_INTEGRAL_BAND_M = 0.2
# How fast the identified lag and dead time may move the model (s per s of flight).
ADAPT_SLEW = 0.1
ADAPT_DRAG_SLEW = 1.0  # 1/s per s
# After a bank candidate's adoption the compensator follows its live drag estimate through a
# low-pass of DRAG_FOLLOW_S (starting from the adopted value). That drag is a gradient estimate
# whose bandwidth grows with the speed squared (DRAG_RATE |v|^2: ~23 1/s at 2.4 m/s): followed
# directly it swung 0.15-0.4 1/s at the flight's own ~1 Hz and drove the mock ArduCopter's `rates`
# helix at 3 m/s off the path (99 cm RMS, 3.6 m max; followed through 1-4 s: 0.7-0.8 cm). The joint
# bank's least-squares drag (FIT_MEMORY_S) is smooth and followed as it is.
DRAG_FOLLOW_S = 2.0
ADAPT_GAIN_SLEW = 0.1  # horizontal gain per s
ADOPT_VERTICAL = True  # a joint model's vertical gain and drag are adopted with it
# identify_lags_up_to: a lag longer than the model's, up to LONG_LAG_MAX_FACTOR x it, is adopted
# only with a dead time of at least LONG_LAG_MIN_DELAY_S and a response (lag + dead time) at most
# LONG_LAG_RESPONSE_SLACK_S longer than the model's: 0.15 s with 0.06-0.08 s. Real ArduCopter SITL's
# rates output fits lag 0.15 s + dead time 0.04-0.06 s: adopting lag 0.2 s with no dead time
# diverged there at once (thrust axis 44 deg off, BRAKE), 0.15 + 0.04 s flew 5.3 cm/s, 0.15 + 0.06 s
# 2.6 cm/s; 0.15 + 0.04 s flew the arducopter mock (0.15 + 0.08 s) at 11 cm, and 0.15 + 0.1 s its
# slower airframes worse than the plain bank (docs/design-decisions.md)
LONG_LAG_MIN_DELAY_S = 0.06
LONG_LAG_MAX_FACTOR = 1.5
LONG_LAG_RESPONSE_SLACK_S = 0.03


# The drag inversion's feedback on the velocity's deviation from the on-path reference velocity,
# per axis (m/s^2): c * (v - v_ref) is positive velocity feedback, so it stays below the law's
# tangential correction bound (limits.max_tangential_accel_m_s2, 1.5 by default) and the law's
# bounded corrections always dominate, whatever drag (0-3 1/s) the identifier fitted. Unbounded, a
# fitted 0.94 1/s ran real PX4 SIH's 3 m/s helix away (3.9 m/s, fence) and a wrong 3 1/s the
# px4-sih mock's (9.8 m/s, 59 m off); the feed-forward at the reference speed stays whole.
MAX_DRAG_FEEDBACK_M_S2 = 0.5


def drag_velocity(drag: Vec, velocity: Vec, reference: Vec) -> Vec:
    """The velocity the drag is inverted at: ``reference + dv`` with ``drag * dv`` the deviation's
    share bounded per axis by MAX_DRAG_FEEDBACK_M_S2 (``dv = velocity - reference`` when smaller)."""
    out = []
    for i in range(3):
        dv = velocity[i] - reference[i]
        c = drag[i]
        if c > 0.0:
            lim = MAX_DRAG_FEEDBACK_M_S2 / c
            dv = lim if dv > lim else (-lim if dv < -lim else dv)
        out.append(reference[i] + dv)
    return (out[0], out[1], out[2])


# Faster than the reference by more than this (m/s), the compensation's push along the velocity
# (drag and disturbance cancelled, c v - d) is scaled by (reference + margin) / speed, as if flown
# at the reference: it cancels drag, so without this it also cancels the vehicle's own braking,
# and once the thrust limits clip the command (a tight turn flown too fast: the centripetal demand
# grows with v^2) the law's bounded braking is clipped with it. Real PX4 SIH's 3 m/s helix ran
# away that way with no adoption at all (acceleration output, d-hat -3 m/s^2 along the velocity,
# 3.9 m/s against 2.4, fence exit). Only ever less push forward: a braking-direction change.
OVERSPEED_MARGIN_M_S = 0.25


def overspeed_bounded(push: Vec, velocity: Vec, reference: Vec) -> Vec:
    """``push`` (m/s^2 ENU) with its component along ``velocity``, when positive, scaled by
    ``(|reference| + OVERSPEED_MARGIN_M_S) / |velocity|`` when that is below one."""
    sp2 = velocity[0] * velocity[0] + velocity[1] * velocity[1] + velocity[2] * velocity[2]
    ref = math.sqrt(reference[0] * reference[0] + reference[1] * reference[1] + reference[2] * reference[2])
    lim = ref + OVERSPEED_MARGIN_M_S
    if sp2 <= lim * lim:
        return push
    sp = math.sqrt(sp2)
    along = (push[0] * velocity[0] + push[1] * velocity[1] + push[2] * velocity[2]) / sp
    if along <= 0.0:
        return push
    k = along * (1.0 - lim / sp) / sp  # the part removed, along the unit velocity
    return (push[0] - k * velocity[0], push[1] - k * velocity[1], push[2] - k * velocity[2])


# The rollback guard (issue 24, safety): after an adoption the tracking is watched for GUARD_WATCH_S;
# when the cross-track error's RMS (low-passed over GUARD_TIME_S) exceeds GUARD_RATIO x a reference
# plus GUARD_MARGIN_M, the compensator goes back to the model it flew before the adoption
# (GUARD_SLEW_FACTOR x the adoption's slew rates, for GUARD_SLEW_S) and the identifier never adopts
# that candidate again. Reference: the RMS low-passed over GUARD_REFERENCE_TIME_S (a flight's own
# turns are in it), the lower of its value at the adoption and the lowest since. Replayed on 214
# real SITL step logs (runs_s30-s33, runs_val: both autopilots, the held-out paths at 1.5 and
# 3 m/s, every output, starts): after none of their 54 adoptions did the 1 s RMS exceed twice the
# reference; a forced bad adoption on the mock is caught 2-3 s after it (docs/design-decisions.md,
# "rollback guard"). The speed error is reported beside it but does not fire it (an open path's
# stop at its end alone moves it 0.5 m/s). Limit: after a far start the reference holds the
# approach for several seconds, so a bad model adopted then is caught only later, if at all.
GUARD_TIME_S = 1.0
GUARD_REFERENCE_TIME_S = 4.0  # the reference's low-pass: a flight's own ups and downs (turns) are in it
GUARD_WATCH_S = 6.0
GUARD_RATIO = 2.0
GUARD_MARGIN_M = 0.06
GUARD_SLEW_FACTOR = 5.0
GUARD_SLEW_S = 2.0


def vertical_lag(model: VehicleModel, delay_s: float) -> float:
    """The vertical lag to fly with an adopted dead time ``delay_s`` (every axis): the model's,
    or none with a dead time longer than the model's vertical one. A longer dead time is the
    horizontal response's (the tilt's); the thrust answers sooner (real PX4 SIH: the vertical
    acceleration 0.05 s after the setpoint, the horizontal 0.18-0.2 s), and a vertical lag on top
    of it made the vertical loop ring: 4 Hz, 2.1-2.8 m/s^2 RMS in the vertical command on every
    real PX4 SIH flight after the joint adoption (docs/design-decisions.md). ``delay_s`` may be
    an array (the batch engine's, per flight)."""
    return model.accel_lag_z_s * (delay_s <= model.vertical_delay_s + 1e-9)


@dataclass(frozen=True)
class RolledBack:
    """What the rollback guard undid (controller's clock, s): the adopted model it rejected, when,
    and the errors' RMS (low-passed) that fired it against their reference."""

    rejected: IdentifiedModel
    at_s: float
    cross_track_rms_m: float
    reference_cross_track_rms_m: float
    speed_error_rms_m_s: float
    reference_speed_error_rms_m_s: float


class InnerLoopCompensator:
    """Stateful, I/O-free. Call :meth:`predict` with each fresh state sample, then :meth:`invert`
    with the law's acceleration; :meth:`invert` records the setpoint it returns as sent.
    ``adapt``: identify a shorter dead time and the horizontal drag in flight
    (:class:`~pf_offboard.control.adaptive.ResponseIdentifier`; the follower turns it on with
    ``Compensation.identify_online`` and the typical model); then :meth:`watch` with each step's
    measured errors lets the rollback guard undo an adoption that flies clearly worse
    (:attr:`rolled_back`, GUARD_*)."""

    def __init__(
        self,
        model: VehicleModel,
        *,
        observer_rad_s: float = Compensation.observer_rad_s,
        max_disturbance_m_s2: float = 4.0,
        speed_integral_rad_s: float = Compensation.integral_rad_s,
        offset_integral_rad_s: float = Compensation.integral_rad_s,
        max_speed_offset_m_s: float = 0.3,
        max_position_offset_m: float = 0.1,
        adapt: bool = False,
    ) -> None:
        if not (math.isfinite(observer_rad_s) and 0.0 <= observer_rad_s <= 50.0):
            raise InputError("gains.disturbance_observer_rad_s", f"must be in [0, 50], got {observer_rad_s!r}")
        if not (math.isfinite(max_disturbance_m_s2) and max_disturbance_m_s2 >= 0.0):
            raise InputError("max_disturbance_m_s2", f"must be >= 0, got {max_disturbance_m_s2!r}")
        self.model = model
        self.delay_s = model.accel_delay_s
        self.delay_z_s = model.vertical_delay_s
        # One prediction horizon for every axis: the law is geometric, so the state it acts on must
        # be one instant. A faster axis group (PX4's thrust answers before its tilt does) has its
        # setpoints held back by the difference, so that every axis acts at t + horizon_s.
        # Predicting each group over its own delay instead gave the law a position at two instants
        # (13 cm apart along a climb at 1.35 m/s): 7.8 cm/s speed error against 1.7 in simulation.
        self.horizon_s = max(self.delay_s, self.delay_z_s)
        self.hold_s: Vec = (self.horizon_s - self.delay_s, self.horizon_s - self.delay_s, self.horizon_s - self.delay_z_s)
        self.lag: Vec = (model.accel_lag_xy_s, model.accel_lag_xy_s, model.accel_lag_z_s)
        self.gain: Vec = (model.accel_gain_xy, model.accel_gain_xy, model.accel_gain_z)
        self.drag: Vec = (model.drag_xy_1_s, model.drag_xy_1_s, model.drag_z_1_s)
        self.observer_rad_s = float(observer_rad_s)
        self.max_disturbance_m_s2 = float(max_disturbance_m_s2)
        # in-flight identification of the dead time, gain and drag together (adaptive.py; None: the
        # model's). A shorter dead time is adopted readily; a longer one only once settled and
        # decisively better: alone (unit gain, no drag) it flew worse (the mock's PX4 SIH preset,
        # 12 of 34 held-out flights; real SIH 8.1 cm), PX4 SIH's whole response flies best
        # (docs/design-decisions.md)
        self.identifier: ResponseIdentifier | None = ResponseIdentifier(
            model.accel_gain_xy, delays_s=[d for d in DELAYS_S if d <= self.delay_s], lags_s=(model.accel_lag_xy_s,),
            initial=(model.accel_lag_xy_s, self.delay_s), longer_delays_s=[d for d in DELAYS_S if d > self.delay_s],
        ) if adapt else None  # fmt: skip
        self._target: tuple[float, float] | None = None
        self._drag_followed: float | None = None  # the live drag, low-passed (DRAG_FOLLOW_S)
        # what the identifier adopted last (its drag then; None: the model flown is the given one)
        self.identified: IdentifiedModel | None = None
        # the rollback guard (GUARD_*): the watch after an adoption, the model restored, the last rollback
        self._watch: tuple[float, float, float, tuple[float, float, Vec, Vec], IdentifiedModel | None, int, int,
                           tuple[float, float] | None] | None = None  # fmt: skip
        self._restore: tuple[float, float, Vec, Vec] | None = None
        self._rollback_until_s = -math.inf
        self.rolled_back: RolledBack | None = None
        self._err_t: float | None = None
        self._cross_ms = self._speed_ms = self._slow_cross_ms = self._slow_speed_ms = 0.0
        self._ref_cross_ms = self._ref_speed_ms = 0.0
        longest = max(self.horizon_s, self.identifier.max_delay_s) if self.identifier is not None else self.horizon_s
        self._history_s = longest + MAX_GAP_S
        for name, value in (("speed_integral_rad_s", speed_integral_rad_s), ("offset_integral_rad_s", offset_integral_rad_s),
                            ("max_speed_offset_m_s", max_speed_offset_m_s), ("max_position_offset_m", max_position_offset_m)):
            if not (math.isfinite(value) and 0.0 <= value <= 100.0):
                raise InputError(f"gains.{name}", f"must be in [0, 100], got {value!r}")
        # Integral action on what the observer cannot see: a model mismatch that is constant in
        # path coordinates (a speed bias, a steady offset in a long turn). PI form: the law sees
        # e + k_i * integral(e), i.e. a reference offset bounded by the max_* values (anti-windup).
        self.speed_integral_rad_s = float(speed_integral_rad_s)
        self.offset_integral_rad_s = float(offset_integral_rad_s)
        self.max_speed_offset_m_s = float(max_speed_offset_m_s)
        self.max_position_offset_m = float(max_position_offset_m)
        self.reset()

    def identify_lags_up_to(self, lag_s: float) -> None:
        """Let the identifier also adopt a longer lag than the model's: up to ``lag_s`` (s; the
        app's ``rates`` output over ArduCopter passes its attitude loop's time constant) and
        LONG_LAG_MAX_FACTOR x the model's, with a dead time of at least LONG_LAG_MIN_DELAY_S (at
        most the model's) and a response at most LONG_LAG_RESPONSE_SLACK_S longer than the
        model's. Real ArduCopter SITL's rates output answers like lag 0.15 s + dead time
        0.04-0.06 s, which the model's lag with any shorter dead time cannot
        describe: the bank adopted late (figure-eight, 25 s) or nothing. Before an adoption only."""
        if self.identifier is None or self.identified is not None or not math.isfinite(lag_s):
            return
        base = self.model.accel_lag_xy_s
        longest = min(lag_s, LONG_LAG_MAX_FACTOR * base) + 1e-9
        lags = [base] + [x for x in LAGS_S if base < x <= longest]
        if len(lags) == 1:
            return
        old = self.identifier
        self.identifier = ResponseIdentifier(old.gain, delays_s=old.delays, lags_s=lags,
                                             initial=(base, self.delay_s),
                                             min_long_lag_delay_s=LONG_LAG_MIN_DELAY_S,
                                             max_long_lag_response_s=base + self.delay_s + LONG_LAG_RESPONSE_SLACK_S,
                                             longer_delays_s=old.longer_delays_s)  # fmt: skip

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget the observer state and the setpoint history."""
        self._t: float | None = None
        self._v_hat: Vec = _ZERO
        self._a_f: Vec = _ZERO  # the model's lag-filter output (acceleration flown, before drag)
        self.disturbance: Vec = _ZERO  # d̂, m/s² ENU
        self._sent: deque[tuple[float, Vec]] = deque()  # (time_s, a_sp ENU) as recorded, in order
        self._t_int: float | None = None
        self.speed_offset_m_s = 0.0  # added to eta2_ref
        self.xi1_offset_m = 0.0  # added to the law's xi1, phi1
        self.phi1_offset_m = 0.0
        if getattr(self, "identifier", None) is not None:
            self.identifier.reset()
        self._err_t = None  # the guard's error level starts over; a watch ends (nothing to compare)
        self._cross_ms = self._speed_ms = self._slow_cross_ms = self._slow_speed_ms = 0.0
        self._watch = None

    def integral_offsets(self) -> tuple[float, float, float]:
        """(eta2_ref offset m/s, xi1 offset m, phi1 offset m) the law adds to its inputs."""
        return self.speed_offset_m_s, self.xi1_offset_m, self.phi1_offset_m

    def integrate(self, time_s: float, speed_error_m_s: float, xi1_m: float, phi1_m: float, free: bool) -> None:
        """Advance the integrators with the measured errors (frozen while ``free`` is False:
        outside the exact tube or while a limit shapes the command — anti-windup)."""
        t_prev, self._t_int = self._t_int, time_s
        if t_prev is None or not free or not (0.0 < time_s - t_prev <= MAX_GAP_S):
            return
        dt = time_s - t_prev
        ks, kx = self.speed_integral_rad_s * dt, self.offset_integral_rad_s * dt
        vmax, pmax = self.max_speed_offset_m_s, self.max_position_offset_m
        self.speed_offset_m_s = min(vmax, max(-vmax, self.speed_offset_m_s + ks * speed_error_m_s))
        if xi1_m * xi1_m + phi1_m * phi1_m <= OFFSET_INTEGRAL_BAND_M * OFFSET_INTEGRAL_BAND_M:
            self.xi1_offset_m = min(pmax, max(-pmax, self.xi1_offset_m + kx * xi1_m))
            self.phi1_offset_m = min(pmax, max(-pmax, self.phi1_offset_m + kx * phi1_m))

    def _pieces(self, t0: float, t1: float, delay: float) -> list[tuple[float, Vec]]:
        """Setpoints acting on the vehicle over (t0, t1] as (duration_s, a_sp ENU) pieces: the one
        recorded at s acts from s + delay on (zero-order hold; before any setpoint: hover, 0)."""
        sent = self._sent
        # the recorded times never decrease, so neither does ts + delay: skip the ones acting by t0
        # (bisection, the same test as one by one)
        k = bisect.bisect_right(sent, t0 + 1e-9, key=lambda e: e[0] + delay)
        cur: Vec = sent[k - 1][1] if k > 0 else _ZERO
        out: list[tuple[float, Vec]] = []
        tau = t0
        for ts, a in itertools.islice(sent, k, None):
            t_on = ts + delay
            if t_on >= t1:
                break
            out.append((t_on - tau, cur))
            tau, cur = t_on, a
        out.append((t1 - tau, cur))
        return out

    def _advance(self, a_f: list[float], v: list[float], p: list[float], t0: float, t1: float) -> None:
        """Integrate the model (lag filter a_f, velocity, position; in place) from t0 to t1, with the
        setpoints acting then (each recorded one acts ``horizon_s`` after it was computed)."""
        for h, u_sp in self._pieces(t0, t1, self.horizon_s):
            if h <= 0.0:
                continue
            for i in range(3):
                u = self.gain[i] * u_sp[i]
                lag = self.lag[i]
                if lag > 0.0:
                    alpha = math.exp(-h / lag)
                    mean_a = u + (a_f[i] - u) * (lag / h) * (1.0 - alpha)
                    a_f[i] = u + (a_f[i] - u) * alpha
                else:
                    mean_a = a_f[i] = u
                acc = mean_a - self.drag[i] * v[i] + self.disturbance[i]
                p[i] += h * (v[i] + 0.5 * h * acc)
                v[i] += h * acc

    # ------------------------------------------------------------------ the three steps
    def predict(self, time_s: float, position: Vec, velocity: Vec) -> tuple[Vec, Vec]:
        """Update the observer with a measured state; return (position, velocity) at ``t + H``."""
        t_prev = self._t
        if t_prev is not None and time_s <= t_prev:
            return self._extrapolate(time_s, position, velocity)  # not newer: no observer update
        if t_prev is None or time_s - t_prev > MAX_GAP_S:
            self.reset()
            self._t = time_s
            self._v_hat = velocity
            return self._extrapolate(time_s, position, velocity)
        dt = time_s - t_prev
        a_f, vh, ph = list(self._a_f), list(self._v_hat), [0.0, 0.0, 0.0]
        self._advance(a_f, vh, ph, t_prev, time_s)
        w = self.observer_rad_s
        l1, l2 = 2.0 * w * dt, w * w * dt
        dmax = self.max_disturbance_m_s2
        dh = list(self.disturbance)
        for i in range(3):
            e = velocity[i] - vh[i]
            vh[i] += l1 * e
            d = dh[i] + l2 * e
            dh[i] = dmax if d > dmax else (-dmax if d < -dmax else d)
        self._a_f = (a_f[0], a_f[1], a_f[2])
        self._v_hat = (vh[0], vh[1], vh[2])
        self.disturbance = (dh[0], dh[1], dh[2])
        self._t = time_s
        if self.identifier is not None:
            self._adapt(t_prev, time_s, velocity)
        return self._extrapolate(time_s, position, velocity)

    def _adapt(self, t_prev: float, time_s: float, velocity: Vec) -> None:
        """Score the candidate models and move the lag and dead time towards the best one at
        ADAPT_SLEW (s per s): the prediction horizon never jumps."""
        assert self.identifier is not None
        ident = self.identifier
        prev_active = ident.active
        best = ident.update(time_s, velocity, self._pieces)
        if best is not None:
            # the rollback guard watches what this adoption does, against the model flown until now
            before = (self.lag[0], self.delay_s, self.gain, self.drag)
            self._watch = (time_s, self._slow_cross_ms, self._slow_speed_ms, before, self.identified,
                           -1 if prev_active is None else prev_active, -1 if ident.active is None else ident.active,
                           self._target)  # fmt: skip
            self._ref_cross_ms, self._ref_speed_ms = self._slow_cross_ms, self._slow_speed_ms
            self._restore = None
            self._target = best
            z = ident.vertical
            self.identified = IdentifiedModel(best[0], best[1], ident.drag_1_s or 0.0, time_s, ident.gain_xy or 1.0,
                                              *(z if z is not None else (self.gain[2], self.drag[2])))  # fmt: skip
            self._drag_followed = ident.drag_1_s
        dt = time_s - t_prev
        if time_s < self._rollback_until_s:  # rolling back: faster than an adoption
            dt *= GUARD_SLEW_FACTOR
        if self._restore is not None:  # rolled back to the initial model
            lag, delay, gain, drag = self._restore
            self._move_to_target(dt, (lag, delay), drag[0], gain[0], (gain[2], drag[2]))
            return
        if self._target is None:
            return
        drag, gain, vertical = ident.drag_1_s, ident.gain_xy, ident.vertical
        if drag is not None and vertical is None:  # the bank's gradient drag: through a low-pass (DRAG_FOLLOW_S)
            f = self._drag_followed
            c = (time_s - t_prev) / DRAG_FOLLOW_S
            self._drag_followed = drag = drag if f is None else f + (c if c < 1.0 else 1.0) * (drag - f)
        elif vertical is not None and not ident.moving:
            # a joint fit while hovering drifts to its prior: followed, the mock's px4-sih hovering
            # at a helix's end went from gain 0.99 and drag 0.98 to 0.82 and 0 in 60 s and its
            # vertical command rang at 5.4 Hz, 2.4 m/s^2 RMS; what is flown stays
            drag = gain = vertical = None
        self._move_to_target(dt, self._target, drag, gain, vertical)

    def watch(self, time_s: float, cross_track_m: float, speed_error_m_s: float) -> None:
        """The rollback guard's step (GUARD_*), with the measured cross-track error (m) and speed
        error (m/s, reference minus along the path): low-pass their squares and, while an adoption
        is watched, roll it back when the tracking has clearly degraded (:attr:`rolled_back`)."""
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
        self._cross_ms += c * (e2 - self._cross_ms)
        self._speed_ms += c * (s2 - self._speed_ms)
        c = dt / GUARD_REFERENCE_TIME_S if dt < GUARD_REFERENCE_TIME_S else 1.0
        self._slow_cross_ms += c * (e2 - self._slow_cross_ms)
        self._slow_speed_ms += c * (s2 - self._slow_speed_ms)
        w = self._watch
        if w is None:
            return
        if time_s - w[0] > GUARD_WATCH_S:
            self._watch = None
            return
        if self._slow_cross_ms < self._ref_cross_ms:
            self._ref_cross_ms = self._slow_cross_ms
        if self._slow_speed_ms < self._ref_speed_ms:
            self._ref_speed_ms = self._slow_speed_ms
        cross, ref_cross = math.sqrt(self._cross_ms), math.sqrt(self._ref_cross_ms)
        if cross <= GUARD_RATIO * ref_cross + GUARD_MARGIN_M:
            return
        _, _, _, before, identified, prev, cand, target = w
        rejected = self.identified
        assert rejected is not None
        self.identifier.reject(cand, None if prev < 0 else prev)
        # back to the model flown before: the initial one as it was, or the previous adoption
        # (which the compensator follows again, as before this one)
        self._restore = before if prev < 0 else None
        self._target = (before[0], before[1]) if prev < 0 else target
        self.identified, self._watch, self._rollback_until_s = identified, None, time_s + GUARD_SLEW_S
        self.rolled_back = RolledBack(rejected, time_s, cross, ref_cross, math.sqrt(self._speed_ms), math.sqrt(self._ref_speed_ms))

    def _move_to_target(self, dt: float, target: tuple[float, float], drag: float | None, gain: float | None = None,
                        vertical: tuple[float, float] | None = None) -> None:  # fmt: skip
        """What an adoption does to the compensator: the lag (the vertical one: :func:`vertical_lag`),
        the dead time (every axis, held back by none), the horizontal drag and gain (and a joint
        model's vertical gain and drag) move towards the adopted candidate's at their slew rates.
        The one place that maps an identified model to the compensator's parameters (mirrored
        by ``pf_offboard.sim.batch.follower._Compensator._move_to_target``)."""
        gain_step, drag_step = ADAPT_GAIN_SLEW * dt, ADAPT_DRAG_SLEW * dt
        drag_before = self.drag
        if gain is not None:
            cur = self.gain[0]
            new_gain = cur + max(-gain_step, min(gain_step, gain - cur))
            self.gain = (new_gain, new_gain, self.gain[2])
        if vertical is not None and ADOPT_VERTICAL:
            gz, cz = self.gain[2], self.drag[2]
            gz += max(-gain_step, min(gain_step, vertical[0] - gz))
            cz += max(-drag_step, min(drag_step, vertical[1] - cz))
            self.gain = (self.gain[0], self.gain[1], gz)
            self.drag = (self.drag[0], self.drag[1], cz)
        step = ADAPT_SLEW * dt
        lag, delay = target
        cur_lag, cur_delay = self.lag[0], self.delay_s
        new_lag = cur_lag + max(-step, min(step, lag - cur_lag))
        new_delay = cur_delay + max(-step, min(step, delay - cur_delay))
        lag_z, cur_lag_z = vertical_lag(self.model, delay), self.lag[2]
        self.lag = (new_lag, new_lag, cur_lag_z + max(-step, min(step, lag_z - cur_lag_z)))
        if drag is not None:
            cur = self.drag[0]
            new_drag = cur + max(-drag_step, min(drag_step, drag - cur))
            self.drag = (new_drag, new_drag, self.drag[2])
        self._hand_over_drag(drag_before)
        self.delay_s = self.delay_z_s = self.horizon_s = new_delay
        self.hold_s = (0.0, 0.0, 0.0)

    def _hand_over_drag(self, drag_before: Vec) -> None:
        """The observer hands over what the model's drag now explains: d̂ += Δdrag ⊙ v̂, so the
        modelled acceleration (``gain·a − drag·v + d̂``) does not jump as the drag slews in. Without
        it d̂ trails the new drag by ~1/observer_rad_s and, at 2-3 m/s, the model's acceleration runs
        0.3-0.5 m/s² off for that long (docs/design-decisions.md, "The joint adoption's drag")."""
        c, v, d, dmax = self.drag, self._v_hat, self.disturbance, self.max_disturbance_m_s2
        if c == drag_before:
            return
        self.disturbance = tuple(min(dmax, max(-dmax, d[i] + (c[i] - drag_before[i]) * v[i])) for i in range(3))  # type: ignore[assignment]

    def _extrapolate(self, time_s: float, position: Vec, velocity: Vec) -> tuple[Vec, Vec]:
        """Integrate the model from the measurement over the setpoints already sent (Smith) to
        ``t + horizon_s``, when the setpoint computed now starts to act. The lag is not predicted
        past that: it stays part of the plant the law's gains must respect (predicting it too,
        with the last setpoint held, over-predicted and excited oscillations in simulation)."""
        if self.horizon_s <= 0.0:
            return position, velocity
        a_f, v, p = list(self._a_f), list(velocity), list(position)
        self._advance(a_f, v, p, time_s, time_s + self.horizon_s)
        return (p[0], p[1], p[2]), (v[0], v[1], v[2])

    def lead(self, accel: Vec, jerk: Vec) -> Vec:
        """``accel + lag ⊙ jerk`` (ENU, m/s²): the acceleration to ask for so that the modelled
        first-order lag flies ``accel`` along a motion with this ``jerk`` (m/s³, the on-path one).

        This lead *replaces* the roll/pitch body-rate feed-forward ω_ff: the autopilot's attitude
        loop (or the app's own in ``rates`` output) tracks the led setpoint, so sending ω_ff as
        well would lead the path twice. With the compensator the command's body rates carry the
        yaw-rate feed-forward only (measured: docs/controller.md, *One lead, not two*)."""
        lag = self.lag
        return (accel[0] + lag[0] * jerk[0], accel[1] + lag[1] * jerk[1], accel[2] + lag[2] * jerk[2])

    def invert(self, time_s: float, accel: Vec, velocity_pred: Vec, velocity_ref: Vec | None = None) -> Vec:
        """Setpoint that makes the modelled vehicle accelerate at ``accel`` (ENU, gravity excluded)
        at the predicted velocity. Not recorded: call :meth:`record` with what is really sent.

        ``velocity_ref`` (the law's on-path velocity, tangent x reference speed): the drag is
        inverted at it plus the predicted velocity's deviation from it, that deviation's share
        bounded per axis to ``MAX_DRAG_FEEDBACK_M_S2`` (:func:`drag_velocity`). Inverting the drag
        at the velocity is positive velocity feedback: with a model drag above the vehicle's (a
        wrong fit, within its bounds) it outgrew the law's bounded tangential correction and the
        vehicle ran away (docs/design-decisions.md, "Drag inversion bounded")."""
        d, c = self.disturbance, self.drag
        if velocity_ref is None:
            b = (c[0] * velocity_pred[0] - d[0], c[1] * velocity_pred[1] - d[1], c[2] * velocity_pred[2] - d[2])
        else:
            vd = drag_velocity(c, velocity_pred, velocity_ref)
            b = overspeed_bounded((c[0] * vd[0] - d[0], c[1] * vd[1] - d[1], c[2] * vd[2] - d[2]), velocity_pred, velocity_ref)
        return ((accel[0] + b[0]) / self.gain[0], (accel[1] + b[1]) / self.gain[1], (accel[2] + b[2]) / self.gain[2])

    @property
    def holds(self) -> bool:
        """True when an axis group's setpoints are held back (the groups' delays differ)."""
        return self.hold_s[0] > 0.0 or self.hold_s[2] > 0.0

    def outgoing(self, time_s: float) -> Vec:
        """The setpoint to send at ``time_s``: per axis, the one recorded ``hold_s`` ago (the latest
        at or before then; the oldest recorded while the history is shorter than the hold). It
        then acts at the recording time + ``horizon_s``, as the prediction assumes."""
        sent = self._sent
        if not sent:
            return _ZERO
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

    def commit(self, time_s: float, setpoint: Vec, clip_thrust: Callable[[Vec], Vec]) -> Vec:
        """The setpoint to send now for the inverted ``setpoint`` computed at ``time_s`` (ENU,
        gravity excluded): kept feasible by ``clip_thrust`` (a thrust vector, gravity included),
        recorded, and — when a group is held back — the :meth:`outgoing` one, feasible too."""
        g = GRAVITY_M_S2

        def feasible(a: Vec) -> Vec:
            fc = clip_thrust((a[0], a[1], a[2] + g))
            return (fc[0], fc[1], fc[2] - g)

        sent = feasible(setpoint)
        self.record(time_s, sent)
        return feasible(self.outgoing(time_s)) if self.holds else sent

    def record(self, time_s: float, setpoint: Vec) -> None:
        """Remember the setpoint the law asked for at ``time_s`` (ENU acceleration, gravity
        excluded; after the thrust limits). Each axis reaches the vehicle after its ``hold_s``
        (:meth:`outgoing`), so every axis of it acts at ``time_s + horizon_s``."""
        sent = self._sent
        if sent and time_s < sent[-1][0]:
            return  # out of order: keep the history monotonic
        sent.append((time_s, setpoint))
        horizon = time_s - self._history_s
        while len(sent) > 1 and sent[1][0] <= horizon:
            sent.popleft()
