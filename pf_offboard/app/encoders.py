"""Backends: encode a core :class:`Command` as a MAVLink setpoint. Encoding only, no decisions.

One encoder per output mode (a level of the paper's Fig. 1 cascade):

- ``acceleration``: SET_POSITION_TARGET_LOCAL_NED, MAV_FRAME_LOCAL_NED, acceleration + yaw +
  yaw rate (position and velocity ignored, type_mask 0x03F);
- ``attitude``: SET_ATTITUDE_TARGET quaternion + normalised thrust, with the body-rate
  feed-forward the autopilot honours next to a quaternion (PX4: yaw rate only; ArduPilot: all);
- ``rates``: the core's rates output (:class:`pf_offboard.control.AttitudeTracker`: the
  attitude-rate law, tilt-prioritised P on the attitude error, time constant τ, bounded body
  rates, plus the core's ω_ff feed-forward; over a rate loop it identifies as fast, through an
  attitude reference with the modelled lag) → SET_ATTITUDE_TARGET body rates + thrust,
  quaternion ignored.

Every value is checked finite before it leaves; a non-finite command is replaced by the safe hold
setpoint (:meth:`Encoder.hold`) and reported through ``Encoded.replaced``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard import frames
from pf_offboard.app.estimator import StateEstimate
from pf_offboard.app.profiles import Profile
from pf_offboard.control.attitude import DEFAULT_ATTITUDE_TIME_CONSTANT_S, AttitudeRateLaw, AttitudeTracker

G_M_S2 = 9.81  # the paper's g; thrust normalisation divides by it

# POSITION_TARGET_TYPEMASK bits
_POS_IGNORE = 0x007
_VEL_IGNORE = 0x038
_ACC_IGNORE = 0x1C0
_YAW_RATE_IGNORE = 0x800
TYPE_MASK_ACCEL_YAW_YAWRATE = _POS_IGNORE | _VEL_IGNORE  # 0x03F
TYPE_MASK_VEL_ACCEL_YAW_YAWRATE = _POS_IGNORE  # 0x007 (ArduPilot "velocity + acceleration")
TYPE_MASK_POSITION_YAW = _VEL_IGNORE | _ACC_IGNORE | _YAW_RATE_IGNORE  # 0x9F8
# ATTITUDE_TARGET_TYPEMASK bits
_ROLL_RATE_IGNORE = 1
_PITCH_RATE_IGNORE = 2
_YAW_RATE_IGNORE_ATT = 4
ATTITUDE_IGNORE = 128
MAV_FRAME_LOCAL_NED = 1

_HOLD_DAMPING_1_S = 1.0  # velocity damping of the acceleration-mode hold (1/s)
_HOLD_ACCEL_MAX_M_S2 = 3.0
_THRUST_PROJECTION_FLOOR = 0.3  # rates mode: keep >= 30 % of the demand while the tilt is still far off
# ArduPilot's angle boost divides the collective by cos(target tilt), the cosine floored at 0.1
# (AC_AttitudeControl_Multi::get_throttle_boosted)
_ANGLE_BOOST_COS_FLOOR = 0.1
# tilt_from_gravity_setpoint: the vertical specific force (g + a_up) it divides by, at least g / 4
# (a demand near free fall; the autopilot's tilt limit then bounds what is flown)
_TILT_FROM_GRAVITY_FLOOR = 0.25


class CommandLike(Protocol):
    """The fields of ``pf_offboard.control.Command`` the encoders read."""

    acceleration: Any
    thrust: float
    attitude: Any
    body_rates: Any
    yaw: float
    yaw_rate: float


@dataclass(frozen=True)
class Encoded:
    """One encoded setpoint. ``replaced`` names why the safe hold was sent instead ("" if not)."""

    message: Any
    thrust_norm: float
    rates_frd_rad_s: tuple[float, float, float] | None
    replaced: str = ""


def thrust_normalised(thrust_m_s2: float, hover_thrust: float) -> float:
    """Mass-normalised thrust (m/s²) → autopilot's 0..1 scale: T / g · hover_thrust, clipped.

    NaN stays NaN (so the finiteness check catches it instead of it becoming zero thrust).
    """
    value = thrust_m_s2 / G_M_S2 * hover_thrust
    return float(min(1.0, max(0.0, value))) if math.isfinite(value) else math.nan


def tilt_from_gravity_setpoint(accel_enu_m_s2: Any) -> tuple[float, float, float]:
    """The acceleration setpoint (ENU, m/s², gravity excluded) to send to an autopilot that tilts
    as if the vertical demand were zero (:attr:`Profile.accel_tilt_from_gravity`), so that it flies
    ``accel_enu_m_s2``.

    Such an autopilot tilts by atan(a_xy / g) and sets the collective for the vertical demand, so
    it flies a_xy (g + a_up) / g horizontally; the horizontal part is scaled by g / (g + a_up). The
    tilt it then commands is the one the whole demand needs, atan(a_xy / (g + a_up)), as in
    ``attitude`` output. The vertical part is sent as it is.
    """
    ax, ay, az = (float(a) for a in accel_enu_m_s2)
    scale = 1.0 / _collective_over_g(az)
    return ax * scale, ay * scale, az


def flown_when_tilting_from_gravity(accel_sent_enu_m_s2: Any) -> tuple[float, float, float]:
    """What an autopilot that tilts from g alone flies for an acceleration setpoint sent to it
    (ENU, m/s², gravity excluded): the horizontal part times (g + a_up) / g, the autopilot's
    collective at least ``g / 4`` (the inverse of :func:`tilt_from_gravity_setpoint`)."""
    ax, ay, az = (float(a) for a in accel_sent_enu_m_s2)
    scale = _collective_over_g(az)
    return ax * scale, ay * scale, az


def _collective_over_g(accel_up_m_s2: float) -> float:
    """(g + a_up) / g, the vertical specific force an autopilot tilting from g alone sets per g of
    its tilt; at least ``_TILT_FROM_GRAVITY_FLOOR``."""
    return max(G_M_S2 + accel_up_m_s2, _TILT_FROM_GRAVITY_FLOOR * G_M_S2) / G_M_S2


def yaw_of(q_enu_flu: NDArray[np.float64]) -> float:
    """ENU yaw (rad) of a body FLU → world ENU attitude."""
    w, x, y, z = q_enu_flu
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def level_attitude(yaw_enu_rad: float) -> NDArray[np.float64]:
    """Level attitude (FLU → ENU) with the given ENU yaw."""
    return np.array([math.cos(yaw_enu_rad / 2.0), 0.0, 0.0, math.sin(yaw_enu_rad / 2.0)])


def _all_finite(values: Any) -> bool:
    """Scalars or short vectors (plain Python on purpose: numpy's per-call overhead dominates)."""
    if isinstance(values, np.ndarray):
        values = values.tolist()
    if isinstance(values, (list, tuple)):
        return all(map(math.isfinite, values))
    return math.isfinite(values)


def attitude_rate_command(
    q_des_enu_flu: NDArray[np.float64],
    q_meas_enu_flu: NDArray[np.float64],
    rates_ff_flu_rad_s: NDArray[np.float64],
    time_constant_s: float,
) -> NDArray[np.float64]:
    """The rates-mode attitude controller (body FLU, rad/s) with the default bounds.

    A shortcut for ``AttitudeRateLaw(time_constant_s).update(...)`` (see
    :mod:`pf_offboard.control.attitude`: tilt-prioritised, bounded body rates).
    """
    return AttitudeRateLaw(time_constant_s).update(q_des_enu_flu, q_meas_enu_flu, rates_ff_flu_rad_s)


def body_z(q_enu_flu: NDArray[np.float64]) -> NDArray[np.float64]:
    """Body z axis (thrust direction) in world ENU."""
    w, x, y, z = q_enu_flu
    return np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])


class Encoder:
    """Encode commands for one output mode and autopilot profile.

    ``hover_thrust`` is the autopilot's normalised hover thrust (0..1) used to scale the
    thrust of attitude / rates setpoints. ``tilt_from_gravity`` (default: the profile's
    :attr:`~Profile.accel_tilt_from_gravity`) makes acceleration setpoints undo the autopilot's
    tilt from g alone (:func:`tilt_from_gravity_setpoint`). ``rate_law`` is the rates-mode attitude controller;
    without it, ``AttitudeRateLaw(time_constant_s)`` (default bounds). ``rates_output``: what
    turns the command into body rates (an :class:`AttitudeTracker` around ``rate_law``; without
    it the law alone; :func:`pf_offboard.app.pipeline.rates_output_for` gives it the core's
    default). Pure but for that tracker's state (a function of the steps fed in, reset at
    activation: ``replay`` reproduces it).
    """

    def __init__(
        self,
        output_mode: str,
        profile: Profile,
        target_system: int,
        target_component: int,
        hover_thrust: float = 0.5,
        time_constant_s: float = DEFAULT_ATTITUDE_TIME_CONSTANT_S,
        rate_law: AttitudeRateLaw | None = None,
        max_body_rate_rad_s: float | None = None,
        tilt_from_gravity: bool | None = None,
        thrust_angle_boost: bool = False,
        rates_output: AttitudeTracker | None = None,
    ) -> None:
        if output_mode not in ("acceleration", "attitude", "rates"):
            raise ValueError(f"unknown output mode {output_mode!r}")
        if not (0.0 < hover_thrust < 1.0):
            raise ValueError(f"hover_thrust must be in (0, 1), got {hover_thrust}")
        if not time_constant_s > 0.0:
            raise ValueError(f"time_constant_s must be positive, got {time_constant_s}")
        self.output_mode = output_mode
        self.profile = profile
        self.target_system = target_system
        self.target_component = target_component
        self.hover_thrust = hover_thrust
        self.rate_law = rate_law if rate_law is not None else AttitudeRateLaw(time_constant_s)
        self.time_constant_s = self.rate_law.time_constant_s
        self.rates_output = rates_output if rates_output is not None else AttitudeTracker(self.rate_law, None)
        # rates mode: the envelope's bound on what is sent (safety.max_body_rate_rad_s); here, in the
        # pure encoder, so that `replay` reproduces it. None: unbounded.
        if max_body_rate_rad_s is not None and not max_body_rate_rad_s > 0.0:
            raise ValueError(f"max_body_rate_rad_s must be positive, got {max_body_rate_rad_s}")
        self.max_body_rate_rad_s = max_body_rate_rad_s
        self.tilt_from_gravity = profile.accel_tilt_from_gravity if tilt_from_gravity is None else bool(tilt_from_gravity)
        # attitude / rates: the autopilot divides the thrust sent by cos(its target tilt) (ArduPilot's
        # ATC_ANGLE_BOOST = 1), so the encoder multiplies it by that cosine: the thrust flown is the
        # core's (measured on ArduCopter SITL without it: vertical acceleration = thrust - g, not
        # thrust cos(tilt) - g; 0.8 m/s^2 too much at 22 deg tilt)
        self.thrust_angle_boost = bool(thrust_angle_boost)

    def with_hover_thrust(self, hover_thrust: float) -> Encoder:
        """The same encoder with the hover thrust read from the autopilot (validated like __init__)."""
        return self._with(hover_thrust, self.tilt_from_gravity, self.thrust_angle_boost)

    def with_tilt_from_gravity(self, tilt_from_gravity: bool) -> Encoder:
        """The same encoder with the autopilot's tilt mapping as read from it (``accel_tilt_param``)."""
        return self._with(self.hover_thrust, tilt_from_gravity, self.thrust_angle_boost)

    def with_thrust_angle_boost(self, thrust_angle_boost: bool) -> Encoder:
        """The same encoder knowing whether the autopilot boosts the thrust by 1 / cos(tilt)
        (``thrust_angle_boost_param`` as read from it)."""
        return self._with(self.hover_thrust, self.tilt_from_gravity, thrust_angle_boost)

    def _with(self, hover_thrust: float, tilt_from_gravity: bool, thrust_angle_boost: bool) -> Encoder:
        return Encoder(
            self.output_mode, self.profile, self.target_system, self.target_component,
            hover_thrust=hover_thrust, rate_law=self.rate_law, max_body_rate_rad_s=self.max_body_rate_rad_s,
            tilt_from_gravity=tilt_from_gravity, thrust_angle_boost=thrust_angle_boost, rates_output=self.rates_output,
        )  # fmt: skip

    def reset(self) -> None:
        """Activation: the rates output starts over (its attitude reference and rate-loop identification)."""
        self.rates_output.reset()

    def _unboost(self, thrust_m_s2: float, q_target_enu_flu: Any) -> float:
        """The thrust to send so that the autopilot's angle boost (if any) flies ``thrust_m_s2``."""
        if not self.thrust_angle_boost:
            return thrust_m_s2
        return thrust_m_s2 * max(float(body_z(np.asarray(q_target_enu_flu, dtype=float))[2]), _ANGLE_BOOST_COS_FLOOR)

    def _accel_ned(self, accel_enu_m_s2: Any) -> NDArray[np.float64]:
        """An acceleration setpoint as sent (NED): what the autopilot flies is ``accel_enu_m_s2``."""
        if self.tilt_from_gravity:
            return frames.enu_to_ned(tilt_from_gravity_setpoint(accel_enu_m_s2))
        return frames.enu_to_ned(accel_enu_m_s2)

    # ------------------------------------------------------------------ path-following setpoints
    def encode(self, cmd: CommandLike, est: StateEstimate, time_boot_ms: int) -> Encoded:
        """The setpoint for a core command; the safe hold if anything is not finite."""
        fields = (cmd.acceleration, cmd.thrust, cmd.attitude, cmd.body_rates, cmd.yaw, cmd.yaw_rate)
        if not all(_all_finite(f) for f in fields):
            # any non-finite output means the core failed this step: trust none of it
            return self._replace(est, time_boot_ms, "non-finite value in command")
        if self.output_mode == "rates" and est.q_enu_flu is None:
            return self._replace(est, time_boot_ms, "no attitude estimate yet (rates mode needs ATTITUDE_QUATERNION)")
        try:
            encoded = self._encode(cmd, est, time_boot_ms)
        except (ValueError, FloatingPointError) as exc:  # frames reject non-finite quaternions
            return self._replace(est, time_boot_ms, f"command not encodable: {exc}")
        if not self._finite_message(encoded.message):
            return self._replace(est, time_boot_ms, "non-finite value in command")
        return encoded

    def _encode(self, cmd: CommandLike, est: StateEstimate, time_boot_ms: int) -> Encoded:
        if self.output_mode == "acceleration":
            accel_ned = self._accel_ned(cmd.acceleration)
            if self.profile.accel_with_velocity:
                # ArduPilot integrates an acceleration-only target into its own velocity and
                # position targets and corrects towards them (Z always). Giving it the measured
                # velocity as the velocity target keeps those targets on the real vehicle, so
                # its correction only acts on its own lag, not as a second outer loop.
                vel_ned = frames.enu_to_ned(est.velocity_enu_m_s)
                mask, vel = TYPE_MASK_VEL_ACCEL_YAW_YAWRATE, (float(vel_ned[0]), float(vel_ned[1]), float(vel_ned[2]))
            else:
                mask, vel = TYPE_MASK_ACCEL_YAW_YAWRATE, (0.0, 0.0, 0.0)
            msg = mavlink2.MAVLink_set_position_target_local_ned_message(
                time_boot_ms, self.target_system, self.target_component, MAV_FRAME_LOCAL_NED,
                mask, 0.0, 0.0, 0.0, *vel,
                float(accel_ned[0]), float(accel_ned[1]), float(accel_ned[2]),
                frames.yaw_enu_to_ned(float(cmd.yaw)), frames.yaw_rate_enu_to_ned(float(cmd.yaw_rate)),
            )  # fmt: skip
            return Encoded(msg, math.nan, None)
        q_des = np.asarray(cmd.attitude, dtype=float)
        if self.output_mode == "attitude":
            rates_frd = frames.flu_to_frd(cmd.body_rates)
            honoured = self.profile.attitude_rates_ff
            mask = 0
            for bit, used in zip((_ROLL_RATE_IGNORE, _PITCH_RATE_IGNORE, _YAW_RATE_IGNORE_ATT), honoured):
                mask |= 0 if used else bit
            sent = tuple(float(r) if used else 0.0 for r, used in zip(rates_frd, honoured))
            thrust = thrust_normalised(self._unboost(float(cmd.thrust), q_des), self.hover_thrust)
            return Encoded(self._attitude_msg(time_boot_ms, mask, q_des, sent, thrust), thrust, sent)  # type: ignore[arg-type]
        # rates: our own attitude loop closes on the measured attitude
        assert est.q_enu_flu is not None
        rates_flu = self.rates_output.update(q_des, est.q_enu_flu, cmd.body_rates, time_s=est.time_s)
        # thrust along the current body z: the part of the demand the vehicle can produce now
        projection = float(np.dot(body_z(q_des), body_z(est.q_enu_flu)))
        # the autopilot's target attitude in rates mode integrates the rates sent: about the measured one
        produced = float(cmd.thrust) * max(projection, _THRUST_PROJECTION_FLOOR)
        thrust = thrust_normalised(self._unboost(produced, est.q_enu_flu), self.hover_thrust)
        rates_frd = frames.flu_to_frd(rates_flu)
        sent = (float(rates_frd[0]), float(rates_frd[1]), float(rates_frd[2]))
        if self.max_body_rate_rad_s is not None:
            from pf_offboard.safety.envelope import bound_body_rates

            sent, _ = bound_body_rates(sent, self.max_body_rate_rad_s)
        return Encoded(self._attitude_msg(time_boot_ms, ATTITUDE_IGNORE, np.array([1.0, 0, 0, 0]), sent, thrust, ned=True), thrust, sent)

    def _attitude_msg(
        self,
        time_boot_ms: int,
        mask: int,
        q_enu_flu: NDArray[np.float64],
        rates_frd: tuple[float, float, float],
        thrust: float,
        ned: bool = False,
    ) -> Any:
        q_ned = q_enu_flu if ned else frames.quat_enu_flu_to_ned_frd(q_enu_flu)
        return mavlink2.MAVLink_set_attitude_target_message(
            time_boot_ms, self.target_system, self.target_component, mask,
            [float(v) for v in q_ned], rates_frd[0], rates_frd[1], rates_frd[2], thrust,
        )  # fmt: skip

    # ------------------------------------------------------------------ other setpoints
    def hold(self, est: StateEstimate, time_boot_ms: int, reason: str = "") -> Encoded:
        """Safe hold in this output mode: brake to a hover at the current heading.

        acceleration: a = −k·v (k = 1/s, |a| ≤ 3 m/s²), current yaw, zero yaw rate;
        attitude: level at the current yaw, hover thrust, no feed-forward;
        rates: our attitude loop towards level, hover thrust.
        """
        yaw = yaw_of(est.q_enu_flu) if est.q_enu_flu is not None else 0.0
        if self.output_mode == "acceleration":
            accel = -_HOLD_DAMPING_1_S * np.asarray(est.velocity_enu_m_s, dtype=float)
            norm = float(np.linalg.norm(accel))
            if not math.isfinite(norm):
                accel = np.zeros(3)
            elif norm > _HOLD_ACCEL_MAX_M_S2:
                accel *= _HOLD_ACCEL_MAX_M_S2 / norm
            accel_ned = self._accel_ned(accel)
            msg = mavlink2.MAVLink_set_position_target_local_ned_message(
                time_boot_ms, self.target_system, self.target_component, MAV_FRAME_LOCAL_NED,
                TYPE_MASK_ACCEL_YAW_YAWRATE, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                float(accel_ned[0]), float(accel_ned[1]), float(accel_ned[2]), frames.yaw_enu_to_ned(yaw), 0.0,
            )  # fmt: skip
            return Encoded(msg, math.nan, None, reason or "hold")
        level = level_attitude(yaw)
        if self.output_mode == "attitude" or est.q_enu_flu is None:
            mask = _ROLL_RATE_IGNORE | _PITCH_RATE_IGNORE | _YAW_RATE_IGNORE_ATT
            return Encoded(self._attitude_msg(time_boot_ms, mask, level, (0.0, 0.0, 0.0), self.hover_thrust), self.hover_thrust, None, reason or "hold")
        rates_frd = frames.flu_to_frd(self.rate_law.update(level, est.q_enu_flu, (0.0, 0.0, 0.0)))
        sent = (float(rates_frd[0]), float(rates_frd[1]), float(rates_frd[2]))
        self.rates_output.reset()  # rates it did not send: its identification and reference start over
        msg = self._attitude_msg(time_boot_ms, ATTITUDE_IGNORE, np.array([1.0, 0, 0, 0]), sent, self.hover_thrust, ned=True)
        return Encoded(msg, self.hover_thrust, sent, reason or "hold")

    def safe(self, yaw_enu_rad: float, time_boot_ms: int, reason: str = "safe") -> Encoded:
        """A setpoint that is safe to hold with no fresh state: it depends on no measurement, so
        the autopilot closes every loop on its own estimate, however long it keeps it (ArduPilot:
        GUID_TIMEOUT) and however stale our state is. Never body rates (open loop).

        acceleration: zero acceleration (PX4: level at its own hover thrust), and where the
        profile takes a velocity target (ArduPilot) a zero one, so it brakes to a stop;
        attitude / rates: level attitude quaternion at ``yaw_enu_rad``, hover thrust.
        """
        yaw = yaw_enu_rad if math.isfinite(yaw_enu_rad) else 0.0
        if self.output_mode == "acceleration":
            mask = TYPE_MASK_VEL_ACCEL_YAW_YAWRATE if self.profile.accel_with_velocity else TYPE_MASK_ACCEL_YAW_YAWRATE
            msg = mavlink2.MAVLink_set_position_target_local_ned_message(
                time_boot_ms, self.target_system, self.target_component, MAV_FRAME_LOCAL_NED,
                mask, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, frames.yaw_enu_to_ned(yaw), 0.0,
            )  # fmt: skip
            return Encoded(msg, math.nan, None, reason)
        mask = _ROLL_RATE_IGNORE | _PITCH_RATE_IGNORE | _YAW_RATE_IGNORE_ATT
        msg = self._attitude_msg(time_boot_ms, mask, level_attitude(yaw), (0.0, 0.0, 0.0), self.hover_thrust)
        return Encoded(msg, self.hover_thrust, None, reason)

    def idle(self, est: StateEstimate, time_boot_ms: int) -> Encoded:
        """Zero-thrust, level attitude setpoint (proof of life while waiting for a throw)."""
        yaw = yaw_of(est.q_enu_flu) if est.q_enu_flu is not None else 0.0
        mask = _ROLL_RATE_IGNORE | _PITCH_RATE_IGNORE | _YAW_RATE_IGNORE_ATT
        return Encoded(self._attitude_msg(time_boot_ms, mask, level_attitude(yaw), (0.0, 0.0, 0.0), 0.0), 0.0, None, "idle")

    def _replace(self, est: StateEstimate, time_boot_ms: int, reason: str) -> Encoded:
        return self.hold(est, time_boot_ms, reason)

    @staticmethod
    def _finite_message(msg: Any) -> bool:
        for name in msg.get_fieldnames():
            value = getattr(msg, name)
            if isinstance(value, float) and not math.isfinite(value):
                return False
            if isinstance(value, (list, tuple)) and not _all_finite(value):
                return False
        return True


def position_setpoint(
    target_system: int,
    target_component: int,
    time_boot_ms: int,
    position_enu_m: NDArray[np.float64],
    yaw_enu_rad: float,
) -> Any:
    """Position + yaw setpoint (used to fly a take-off in OFFBOARD on PX4)."""
    p = frames.enu_to_ned(position_enu_m)
    return mavlink2.MAVLink_set_position_target_local_ned_message(
        time_boot_ms, target_system, target_component, MAV_FRAME_LOCAL_NED, TYPE_MASK_POSITION_YAW,
        float(p[0]), float(p[1]), float(p[2]), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, frames.yaw_enu_to_ned(yaw_enu_rad), 0.0,
    )  # fmt: skip
