"""The pure heart of ``fly``: MAVLink telemetry in → (setpoint message, StepRecord) out.

No sockets, no clocks: the setpoint is a deterministic function of the messages fed in (their
timestamps included), so ``replay`` re-feeding a flight's recorded telemetry reproduces the
setpoints that flew. ``fly``, ``sim`` and ``replay`` all use this class.

    pipe = Pipeline(follower, encoder)
    for msg in telemetry:
        pipe.on_message(msg)
        out = pipe.step()          # None unless a fresh state sample arrived since the last step
        if out: send(out.setpoint); log(out.record)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pf_offboard.app.encoders import Encoded, Encoder, yaw_of
from pf_offboard.app.estimator import Estimator, StateEstimate
from pf_offboard.logs.steplog import StepRecord
from pf_offboard.logs.summary import identified_event, rolled_back_event

_NAN3 = (math.nan, math.nan, math.nan)
_NAN4 = (math.nan, math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class Step:
    """One controller step: the message to send, its log record, the inputs it came from."""

    setpoint: Any  # pymavlink message (SET_POSITION_TARGET_LOCAL_NED / SET_ATTITUDE_TARGET)
    record: StepRecord
    command: Any | None  # pf_offboard.control.Command, None when the core failed
    estimate: StateEstimate
    encoded: Encoded
    # the estimator reset this step's sample came with: the jump of the position estimate (ENU m;
    # None: no reset), for the envelope (safety.max_estimator_reset_m)
    estimator_reset_enu_m: Any = None


def time_boot_ms(est: StateEstimate) -> int:
    """Setpoint timestamp from the state sample's own (autopilot) clock."""
    return int(round(est.time_s * 1000.0)) & 0xFFFFFFFF


def fit_identification_to_output(follower: Any, output_mode: str, profile: Any, time_constant_s: float) -> None:
    """Tell the follower's in-flight identification what the output adds to the inner loop: an
    autopilot that flies the ``rates`` output through its own attitude target
    (``Profile.rates_through_attitude_target``: ArduCopter), under the app's attitude loop
    (``time_constant_s``), answers with a longer lag and a shorter dead time than the model's: the
    identifier may then adopt a longer lag (``InnerLoopCompensator.identify_lags_up_to``). Used by
    :class:`Pipeline` and the batch engine alike."""
    comp = getattr(follower, "compensator", None)
    if (output_mode == "rates" and getattr(profile, "rates_through_attitude_target", False)
            and comp is not None and hasattr(comp, "identify_lags_up_to")):  # fmt: skip
        comp.identify_lags_up_to(time_constant_s)


def rates_output_for(follower: Any, profile: Any, rate_law: Any) -> Any:
    """The ``rates`` output's attitude controller for this follower and autopilot: the core's
    default (:meth:`pf_offboard.control.AttitudeTracker.from_vehicle` on the follower's inner-loop
    model: the law, and an attitude reference with the modelled lag once the rate loop is
    identified fast), around ``rate_law``. The law alone when the follower has no inner-loop model
    or the autopilot flies rates through its own attitude target
    (``Profile.rates_through_attitude_target``, ArduCopter: the response to the reference's faster
    rates is its attitude loop's, not a rate loop's). Used by :class:`Pipeline` and the batch engine."""
    from pf_offboard.control.attitude import REFERENCE_LAG_FRACTION, AttitudeTracker

    model = getattr(getattr(follower, "compensator", None), "model", None)
    lag = float(getattr(model, "accel_lag_xy_s", 0.0) or 0.0)
    if lag <= 0.0 or getattr(profile, "rates_through_attitude_target", False):
        return AttitudeTracker(rate_law, None)
    return AttitudeTracker(rate_law, REFERENCE_LAG_FRACTION * lag, identify_rate_loop=True)


class Pipeline:
    """Estimator → core → encoder, stepped once per fresh state sample.

    ``follower`` is a :class:`pf_offboard.control.PathFollower` (anything with
    ``update(position_enu_m, velocity_enu_m_s) -> Command`` and ``reset()``), or the
    :class:`pf_offboard.control.TrajectoryTracker` baseline (``needs_time``: it gets each sample's
    time and is reset on activation, when its schedule starts).
    """

    @property
    def tilt_limit_deg(self) -> float | None:
        """The tilt limit the follower plans and flies with (deg: the config's, or the autopilot's
        if lower), None for a follower without limits."""
        limits = getattr(self.follower, "limits", None)
        return None if limits is None else float(limits.max_tilt_deg)

    def __init__(self, follower: Any, encoder: Encoder, estimator: Estimator | None = None) -> None:
        self.follower = follower
        self.encoder = encoder
        fit_identification_to_output(follower, encoder.output_mode, encoder.profile, encoder.time_constant_s)
        if encoder.output_mode == "rates":
            encoder.rates_output = rates_output_for(follower, encoder.profile, encoder.rate_law)
        self.estimator = estimator if estimator is not None else Estimator()
        self._stepped_sample = 0
        self.replaced_steps = 0  # steps where the safe hold was sent instead of the command
        # a follower with inner-loop compensation needs each sample's time (observer, predictor)
        self._timed = getattr(follower, "compensator", None) is not None or bool(getattr(follower, "needs_time", False))
        self._was_active = False
        self._identified: Any = None  # the last adopted inner-loop model logged
        self._rolled_back: Any = None  # the last rollback logged
        self._rates_reference = False  # the rates output's attitude reference engaged (logged when it changes)
        speed = getattr(follower, "speed", math.nan)
        self.speed_ref_m_s = float(speed) if isinstance(speed, (int, float)) else math.nan
        # with a speed profile the reference varies along the path: log each step's eta2_ref
        self._profiled = getattr(follower, "profile", None) is not None

    def on_message(self, msg: Any) -> bool:
        """Feed one received message; True if it brought a fresh state sample."""
        return self.estimator.on_message(msg)

    @property
    def fresh(self) -> bool:
        est = self.estimator.latest
        return est is not None and est.sample != self._stepped_sample

    def mark_consumed(self) -> None:
        """Forget the fresh sample without stepping the controller (used before activation)."""
        est = self.estimator.latest
        if est is not None:
            self._stepped_sample = est.sample

    def step(self, mode: str = "following", active: bool = True, event: str = "") -> Step | None:
        """Run the controller on the latest state if it is fresh; else None."""
        est = self.estimator.latest
        if est is None or est.sample == self._stepped_sample:
            return None
        self._stepped_sample = est.sample
        events = [event] if event else []
        if active and not self._was_active:
            self.encoder.reset()  # the rates output starts over at activation
            self._rates_reference = False
            # yaw: {mode: hold} keeps the heading the vehicle has now: no turn while the approach
            # tilts it (a 90° turn at the yaw-rate bound put a light vehicle's motor at 0)
            hold = getattr(self.follower, "hold_heading", None)
            if hold is not None and est.q_enu_flu is not None:
                heading = yaw_of(est.q_enu_flu)
                if hold(heading):
                    events.append(f"heading_held={math.degrees(heading):.1f}")
        if active and not self._was_active and self._timed:
            # activation: what the observer learnt while the setpoints were not flown (a throw in
            # free fall, the proof-of-life stream) is not the vehicle's response: start over
            self.follower.reset()
            events.append("compensator_reset")
        self._was_active = active
        reset_enu_m = None
        if self.estimator.reset_pending:
            self.estimator.reset_pending = False
            self.follower.reset()  # the position may have jumped: redo the global projection
            reason = self.estimator.reset_reason
            events.append(f"estimator_reset: {reason}" if reason else "estimator_reset")
            reset_enu_m = self.estimator.last_reset_enu_m  # None: of unknown size (a clock re-anchoring)
        stamp = time_boot_ms(est)
        try:
            if self._timed:
                cmd = self.follower.update(est.position_enu_m, est.velocity_enu_m_s, time_s=est.time_s)
            else:
                cmd = self.follower.update(est.position_enu_m, est.velocity_enu_m_s)
        except (ArithmeticError, ValueError) as exc:  # never let a core failure become silence
            cmd = None
            encoded = self.encoder.hold(est, stamp, f"controller failed: {exc}")
        else:
            encoded = self.encoder.encode(cmd, est, stamp)
        comp = getattr(self.follower, "compensator", None)
        rb = getattr(comp, "rolled_back", None)
        if rb is not None and rb is not self._rolled_back:  # the guard undid an adoption: logged once
            self._rolled_back = rb
            m = rb.rejected
            events.append(rolled_back_event(m.lag_s, m.delay_s, m.drag_1_s, m.gain_xy, rb.cross_track_rms_m, rb.reference_cross_track_rms_m,
                                            rb.speed_error_rms_m_s, rb.reference_speed_error_rms_m_s))  # fmt: skip
            self._identified = getattr(comp, "identified", None)  # the model flown before: no new adoption
        model = getattr(comp, "identified", None)
        if model is not None and model is not self._identified:  # an adoption: logged once, for the summary and replay
            self._identified = model
            events.append(identified_event(model.lag_s, model.delay_s, model.drag_1_s, model.gain_xy, model.gain_z, model.drag_z_1_s))
        engaged = bool(getattr(self.encoder.rates_output, "reference_engaged", False)) and self.encoder.output_mode == "rates"
        if engaged != self._rates_reference:  # the rates output engaged (dropped) its attitude reference
            self._rates_reference = engaged
            best = getattr(getattr(self.encoder.rates_output, "rate_loop", None), "best", None)
            loop = f" (rate loop lag {best[0]:.3f} s, dead time {best[1]:.3f} s)" if best is not None else ""
            events.append(f"rates_reference: {'on' if engaged else 'off'}{loop}")
        if encoded.replaced:
            self.replaced_steps += 1
            events.append(f"hold: {encoded.replaced}")
        record = self._record(est, cmd, mode, active, ";".join(events))
        return Step(encoded.message, record, cmd, est, encoded, reset_enu_m)

    def _record(self, est: StateEstimate, cmd: Any | None, mode: str, active: bool, event: str) -> StepRecord:
        if cmd is None:  # the core failed: log the state, NaN commands (the hold went out)
            nan = math.nan
            return StepRecord(
                time_s=est.time_s, mode=mode, active=active, position_enu_m=est.position_enu_m,
                velocity_enu_m_s=est.velocity_enu_m_s, lam=nan, eta1_m=nan, eta2_m_s=nan, xi1_m=nan,
                xi2_m_s=nan, phi1_m=nan, phi2_m_s=nan, cross_track_m=nan, speed_ref_m_s=self.speed_ref_m_s,
                accel_cmd_enu_m_s2=_NAN3, thrust_cmd_m_s2=nan, q_cmd_enu_flu=_NAN4, rates_cmd_flu_rad_s=_NAN3,
                yaw_cmd_rad=nan, yaw_rate_cmd_rad_s=nan, sat_tangential=False, sat_transversal=False,
                sat_tilt=False, sat_thrust=False, sat_approach_speed=False, event=event,
            )  # fmt: skip
        st, sat = cmd.state, cmd.saturation
        return StepRecord(
            time_s=est.time_s,
            mode=mode,
            active=active,
            position_enu_m=est.position_enu_m,
            velocity_enu_m_s=est.velocity_enu_m_s,
            lam=float(cmd.lam),
            eta1_m=float(st.eta1),
            eta2_m_s=float(st.eta2),
            xi1_m=float(st.xi1),
            xi2_m_s=float(st.xi2),
            phi1_m=float(st.phi1),
            phi2_m_s=float(st.phi2),
            cross_track_m=float(cmd.cross_track_m),
            # the reference the law tracked this step (a speed profile's, the start ramp's)
            speed_ref_m_s=float(cmd.eta2_ref_m_s) if math.isfinite(cmd.eta2_ref_m_s) else self.speed_ref_m_s,
            accel_cmd_enu_m_s2=np.asarray(cmd.acceleration, dtype=float),
            thrust_cmd_m_s2=float(cmd.thrust),
            q_cmd_enu_flu=np.asarray(cmd.attitude, dtype=float),
            rates_cmd_flu_rad_s=np.asarray(cmd.body_rates, dtype=float),
            yaw_cmd_rad=float(cmd.yaw),
            yaw_rate_cmd_rad_s=float(cmd.yaw_rate),
            sat_tangential=bool(sat.tangential),
            sat_transversal=bool(sat.transversal),
            sat_tilt=bool(sat.tilt),
            sat_thrust=bool(sat.thrust),
            sat_approach_speed=bool(sat.approach_speed),
            event=event,
        )
