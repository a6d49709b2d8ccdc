"""Autopilot profiles: what PX4 and ArduPilot Copter call things and what they honour.

Pure data and pure functions (no I/O). The facts come from the autopilots' source, collected in
``shared/notes/autopilot-facts.md``; the choices made from them are documented in ``docs/app.md``.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from pf_offboard.errors import InputError

# MAVLink enum values used here (common.xml); kept local so this module imports nothing heavy.
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAV_AUTOPILOT_INVALID = 8
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1

OUTPUT_MODES: tuple[str, ...] = ("acceleration", "attitude", "rates")


class Autopilot(enum.Enum):
    """The autopilot family on the other end of the link."""

    PX4 = "px4"
    ARDUPILOT = "ardupilot"


@dataclass(frozen=True)
class ModeRequest:
    """Arguments of MAV_CMD_DO_SET_MODE for one flight mode (param1 = base mode flag)."""

    name: str
    param2: float  # PX4 main mode / ArduPilot custom mode number
    param3: float  # PX4 sub mode; 0 for ArduPilot


def px4_custom_mode(main: int, sub: int = 0) -> int:
    """PX4 HEARTBEAT custom_mode: ``{uint16 reserved; uint8 main_mode; uint8 sub_mode}``."""
    return (main << 16) | (sub << 24)


@dataclass(frozen=True)
class Profile:
    """Everything the app needs to know about one autopilot family.

    ``offboard`` is the mode the app flies in (PX4 OFFBOARD, ArduPilot GUIDED); ``hold`` and
    ``land`` are the hand-back modes. ``custom_mode`` values are what HEARTBEAT reports.
    """

    autopilot: Autopilot
    offboard: ModeRequest
    offboard_custom_mode: int
    hold: ModeRequest
    hold_custom_mode: int
    land: ModeRequest
    land_custom_mode: int
    hover_thrust_param: str
    # body-rate feed-forward honoured next to an attitude quaternion: PX4 uses only the yaw rate,
    # ArduPilot uses all three (it advances its target attitude with them).
    attitude_rates_ff: tuple[bool, bool, bool]
    # acceleration output sent with the measured velocity as velocity target (ArduPilot: see encoders)
    accel_with_velocity: bool = False
    # the hover-thrust parameter is only where the autopilot's own estimate starts (PX4: its
    # hover-thrust estimator never writes MPC_THR_HOVER back): attitude / rates output measure the
    # thrust of its attitude target while it holds instead (app/hover.py). ArduCopter learns
    # MOT_THST_HOVER in flight and saves it (MOT_HOVER_LEARN 2): its parameter is read as it is.
    hover_thrust_measured: bool = False
    # How the autopilot turns an acceleration setpoint into a tilt: from the horizontal demand
    # against g alone, ignoring the vertical demand (PX4 with MPC_ACC_DECOUPLE = 1, its default;
    # ArduPilot's accel_to_lean_angles always). Its collective still meets the vertical demand, so
    # the horizontal acceleration flown is a_xy (g + a_up) / g: 15 % more or less on a path that
    # climbs or sinks at 1.5 m/s² (the encoder divides it out, see encoders.tilt_from_gravity_setpoint).
    accel_tilt_from_gravity: bool = True
    # the parameter that says so (1: tilt from g alone; 0: from the whole demand), or None
    accel_tilt_param: str | None = None
    # attitude / rates: the parameter that, at 1, makes the autopilot divide the thrust sent by
    # cos(target tilt) (ArduPilot's ATC_ANGLE_BOOST, default 1), or None (PX4 flies the thrust as sent)
    thrust_angle_boost_param: str | None = None
    # acceleration: the parameters bounding the tilt the autopilot flies an acceleration setpoint
    # with, as (name, degrees per unit) in order; the first positive answer is the limit (0 means
    # "see the next"). PX4: MPC_TILTMAX_AIR (deg). ArduPilot (AC_PosControl::get_lean_angle_max_rad):
    # PSC_ANGLE_MAX (deg) unless 0, then ANGLE_MAX (cdeg). Attitude / rate targets are not clipped
    # by either (PX4 offboard attitude; ArduPilot's GUIDED angle control).
    accel_tilt_limit_params: tuple[tuple[str, float], ...] = ()
    # rates: the autopilot integrates the body rates sent into its own attitude target and closes
    # its attitude loop on it (ArduCopter, AC_AttitudeControl::input_rate_bf_roll_pitch_yaw_rads),
    # so under the app's attitude loop the response is a longer lag with a short dead time; the
    # in-flight identification may then adopt a lag up to 1.5 x the model's (app.pipeline). PX4
    # tracks the rates directly.
    rates_through_attitude_target: bool = False
    # flight.velocity_correction_s when the config leaves it ``auto`` (s; None: off): how fast the
    # app makes the velocity estimate agree with the position estimate's derivative
    # (pf_offboard.app.estimator). PX4's EKF2 reports a velocity 10-40 cm/s off its own position's
    # derivative (SIH): 0.1 s made real PX4 SIH flights 3.1-4.3 cm (0.3 s: 3.9-6.3). ArduPilot's EKF3
    # agrees with itself: 0.1 s only added the position derivative's noise (real ArduCopter `rates`
    # figure-eight 3.2-3.4 cm/s against 2.6 at 0.3 s). docs/design-decisions.md, The estimate
    velocity_correction_s: float | None = 0.3
    # HEARTBEAT custom_mode bits that identify our mode (PX4: the main mode only; it leaves the
    # sub mode 0 in OFFBOARD)
    offboard_mode_mask: int = 0xFFFFFFFF
    # PX4 packs an INT32 parameter's bytes into PARAM_VALUE's float; ArduPilot casts it
    params_bytewise: bool = False
    # GUID_OPTIONS bits each output mode needs, as (output mode, bits) pairs (ArduPilot only)
    guid_options: tuple[tuple[str, int], ...] = ()
    # output modes refused by default, as (output mode, why) pairs (see output_mode_refusal)
    refused_outputs: tuple[tuple[str, str], ...] = ()
    # HEARTBEAT custom_mode -> human-readable name
    mode_names: Callable[[int], str] = str
    # modes only the autopilot's own failsafe (or the operator) chooses when we did not ask for them:
    # return and land modes; never overridden by the app (see pf_offboard.app.modes)
    failsafe_custom_modes: tuple[int, ...] = ()

    @property
    def name(self) -> str:
        return self.autopilot.value

    def tilts_from_gravity(self, reported: float | None) -> bool:
        """Whether the autopilot tilts from g alone for acceleration setpoints, given the value it
        reported for :attr:`accel_tilt_param` (None, or anything but 0 / 1: its default)."""
        if reported in (0.0, 1.0):
            return reported == 1.0
        return self.accel_tilt_from_gravity

    def accel_tilt_limit_deg(self, reported: Mapping[str, float]) -> float | None:
        """The autopilot's acceleration tilt limit (deg) from the values it reported for
        :attr:`accel_tilt_limit_params` (the first positive one rules); None without a limit
        parameter or an answer. ValueError naming the parameter for NaN, < 0 or > 90 deg (0 on the
        last one)."""
        for name, deg_per_unit in self.accel_tilt_limit_params:
            if name not in reported:
                return None
            value = float(reported[name])
            deg = value * deg_per_unit
            last = name == self.accel_tilt_limit_params[-1][0]
            if not (math.isfinite(deg) and 0.0 <= deg <= 90.0) or (deg == 0.0 and last):
                raise ValueError(f"{name} = {value:g} is not a tilt limit (0 < tilt <= 90 deg)")
            if deg > 0.0:
                return deg
        return None

    def is_offboard(self, custom_mode: int) -> bool:
        """True when a HEARTBEAT custom_mode says the vehicle is in our mode."""
        mask = self.offboard_mode_mask
        return custom_mode & mask == self.offboard_custom_mode & mask

    def mode_name(self, custom_mode: int) -> str:
        """Human-readable mode for the status line."""
        return self.mode_names(custom_mode)

    def custom_mode_of(self, mode: ModeRequest) -> int:
        """The HEARTBEAT custom_mode of one of our modes (offboard, hold, land)."""
        for ours, custom in ((self.offboard, self.offboard_custom_mode), (self.hold, self.hold_custom_mode), (self.land, self.land_custom_mode)):
            if mode is ours:
                return custom
        raise KeyError(mode.name)

    def required_guid_options(self, output_mode: str) -> int:
        """GUID_OPTIONS bits an output mode needs (ArduPilot only; 0 for PX4).

        - attitude / rates: bit 3 (8), "thrust as thrust"; without it ArduPilot reads the
          thrust field as a climb-rate demand and would fly a misread command.
        - acceleration: bit 4 (16), "do not stabilise position XY": ArduPilot integrates its
          velocity target into a position target and corrects towards it; we send the measured
          velocity as the velocity target (see encoders), and with bit 4 that XY position
          correction, a second outer loop fighting the path follower, is off.
        """
        return dict(self.guid_options).get(output_mode, 0)


def px4_mode_name(custom_mode: int) -> str:
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    mains = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 4: "AUTO", 5: "ACRO", 6: "OFFBOARD", 7: "STABILIZED"}
    subs = {2: "TAKEOFF", 3: "LOITER", 4: "MISSION", 5: "RTL", 6: "LAND"}
    text = mains.get(main, f"MODE{main}")
    return f"{text}.{subs.get(sub, sub)}" if main == 4 else text


def ardupilot_mode_name(custom_mode: int) -> str:
    names = {0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 9: "LAND", 16: "POSHOLD", 17: "BRAKE", 18: "THROW"}
    return names.get(custom_mode, f"MODE{custom_mode}")


EXPERIMENTAL_OUTPUT_FLAG = "--experimental-output"

# Measured on the real autopilots: ArduPilot integrates acceleration targets into its own
# velocity/position targets and jerk-limits them (PSC_JERK_XY/Z); on ArduCopter SITL
# `acceleration` output oscillated by metres even with PSC_JERK_XY/Z = 50, while `attitude`
# (1.5 Hz / 1.0 gains: 6.6 cm cross-track RMS) and `rates` (τ = 0.25 s: 4 cm) followed the path.
_ARDUPILOT_ACCELERATION_REFUSAL = (
    "ArduPilot jerk-limits and integrates acceleration targets (PSC_JERK_XY/Z); on ArduCopter SITL this output "
    "oscillated by metres even with PSC_JERK_XY/Z = 50. Use --output attitude on ArduPilot "
    f"(or rates); {EXPERIMENTAL_OUTPUT_FLAG} flies it anyway"
)


PX4 = Profile(
    autopilot=Autopilot.PX4,
    offboard=ModeRequest("OFFBOARD", 6, 0),
    offboard_custom_mode=px4_custom_mode(6),
    hold=ModeRequest("AUTO.LOITER", 4, 3),
    hold_custom_mode=px4_custom_mode(4, 3),
    land=ModeRequest("AUTO.LAND", 4, 6),
    land_custom_mode=px4_custom_mode(4, 6),
    hover_thrust_param="MPC_THR_HOVER",
    hover_thrust_measured=True,
    attitude_rates_ff=(False, False, True),
    accel_tilt_param="MPC_ACC_DECOUPLE",
    accel_tilt_limit_params=(("MPC_TILTMAX_AIR", 1.0),),
    velocity_correction_s=0.1,
    offboard_mode_mask=0xFF << 16,
    params_bytewise=True,
    mode_names=px4_mode_name,
    # AUTO.RTL, AUTO.LAND, AUTO.PRECLAND; DESCEND (main 4 sub 9 in some versions is PRECLAND)
    failsafe_custom_modes=(px4_custom_mode(4, 5), px4_custom_mode(4, 6), px4_custom_mode(4, 9)),
)

ARDUPILOT = Profile(
    autopilot=Autopilot.ARDUPILOT,
    offboard=ModeRequest("GUIDED", 4, 0),
    offboard_custom_mode=4,
    # BRAKE, not LOITER: LOITER climbs / descends with the pilot's throttle stick, which is down after
    # a GUIDED take-off (and in SITL with nobody at the sticks: it hit the ground at 2.4 m/s 1.5 s
    # after a hand-back); BRAKE stops and holds, ignoring the sticks, until the pilot switches mode
    hold=ModeRequest("BRAKE", 17, 0),
    hold_custom_mode=17,
    land=ModeRequest("LAND", 9, 0),
    land_custom_mode=9,
    hover_thrust_param="MOT_THST_HOVER",
    attitude_rates_ff=(True, True, True),
    accel_with_velocity=True,
    thrust_angle_boost_param="ATC_ANGLE_BOOST",
    accel_tilt_limit_params=(("PSC_ANGLE_MAX", 1.0), ("ANGLE_MAX", 0.01)),
    rates_through_attitude_target=True,
    guid_options=(("attitude", 8), ("rates", 8), ("acceleration", 16)),
    refused_outputs=(("acceleration", _ARDUPILOT_ACCELERATION_REFUSAL),),
    mode_names=ardupilot_mode_name,
    failsafe_custom_modes=(6, 9, 21),  # RTL, LAND, SMART_RTL
)

PROFILES: dict[str, Profile] = {"px4": PX4, "ardupilot": ARDUPILOT}


def profile_from_heartbeat(autopilot: int) -> Profile:
    """Profile for a HEARTBEAT ``autopilot`` field; anything else is an error naming the value."""
    if autopilot == MAV_AUTOPILOT_PX4:
        return PX4
    if autopilot == MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    raise InputError(
        "--autopilot",
        f"HEARTBEAT autopilot={autopilot} is neither PX4 (12) nor ArduPilot (3); pass --autopilot px4|ardupilot",
    )


def select_profile(flag: str | None, heartbeat_autopilot: int) -> Profile:
    """The ``--autopilot`` flag if given (``auto`` or None means detect from HEARTBEAT)."""
    if flag in (None, "auto"):
        return profile_from_heartbeat(heartbeat_autopilot)
    try:
        return PROFILES[flag]
    except KeyError:
        raise InputError("--autopilot", f"unknown autopilot {flag!r}; use auto, px4 or ardupilot") from None


def check_output_mode(output_mode: str) -> str:
    """Validate an output mode name."""
    if output_mode not in OUTPUT_MODES:
        raise InputError("--output", f"unknown output mode {output_mode!r}; use one of {', '.join(OUTPUT_MODES)}")
    return output_mode


def output_mode_refusal(profile: Profile, output_mode: str) -> str:
    """Why ``fly`` refuses ``output_mode`` on this autopilot by default ("" if it does not)."""
    return dict(profile.refused_outputs).get(output_mode, "")


def is_armed(base_mode: int) -> bool:
    """Armed flag of a HEARTBEAT base_mode (bit 128, same on both autopilots)."""
    return bool(base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
