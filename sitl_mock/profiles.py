"""What differs between the ``px4`` and ``ardupilot`` profiles: identity, modes, parameters, streams.

Pure data (frozen dataclasses and tuples); the behaviour that uses it lives in
:mod:`sitl_mock.autopilot`. Encodings follow the autopilots' sources (see
``docs/sitl-mock.md`` and the shared notes ``autopilot-facts.md``).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from pymavlink.dialects.v20 import common as mavlink


class Behaviour(enum.Enum):
    """How the autopilot flies a mode (the mock's model of it)."""

    OFFBOARD = "offboard"  # PX4 OFFBOARD / ArduPilot GUIDED: the client's setpoints
    HOLD = "hold"  # position hold at the stopping point (PX4 LOITER/POSCTL, AP LOITER/POSHOLD)
    BRAKE = "brake"  # ArduPilot BRAKE: stop, then hold
    LEVEL = "level"  # manual attitude modes with centred sticks: level, hold climb rate 0
    TAKEOFF = "takeoff"
    LAND = "land"
    RTL = "rtl"


@dataclass(frozen=True)
class ModeSpec:
    """One flight mode: its name, HEARTBEAT custom_mode and the mock's behaviour."""

    name: str
    custom_mode: int
    behaviour: Behaviour
    base_flags: int  # MAV_MODE_FLAG bits other than SAFETY_ARMED / CUSTOM_MODE_ENABLED
    armable: bool = True


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 custom_mode: ``{uint16 reserved; uint8 main_mode; uint8 sub_mode}`` little-endian."""
    return (main_mode << 16) | (sub_mode << 24)


_MANUAL = mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
_AUTO = (
    mavlink.MAV_MODE_FLAG_AUTO_ENABLED
    | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
)
_STAB = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
_GUIDED = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED

PX4_MODES: tuple[ModeSpec, ...] = (
    ModeSpec("MANUAL", px4_custom_mode(1), Behaviour.LEVEL, _MANUAL),
    ModeSpec("ALTCTL", px4_custom_mode(2), Behaviour.LEVEL, _MANUAL),
    ModeSpec("POSCTL", px4_custom_mode(3), Behaviour.HOLD, _MANUAL),
    ModeSpec("AUTO.TAKEOFF", px4_custom_mode(4, 2), Behaviour.TAKEOFF, _AUTO),
    ModeSpec("AUTO.LOITER", px4_custom_mode(4, 3), Behaviour.HOLD, _AUTO),
    ModeSpec("AUTO.RTL", px4_custom_mode(4, 5), Behaviour.RTL, _AUTO),
    ModeSpec("AUTO.LAND", px4_custom_mode(4, 6), Behaviour.LAND, _AUTO),
    ModeSpec("ACRO", px4_custom_mode(5), Behaviour.LEVEL, mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED),
    # Observed on PX4 SITL: base_mode 0x91 armed in OFFBOARD, i.e. only STABILIZE besides armed/custom.
    ModeSpec("OFFBOARD", px4_custom_mode(6), Behaviour.OFFBOARD, _STAB),
    ModeSpec("STABILIZED", px4_custom_mode(7), Behaviour.LEVEL, _MANUAL),
)

# ArduCopter control_mode numbers (Copter/mode.h). allows_arming() is false for AUTO (by
# default), RTL, LAND, BRAKE, CIRCLE, SMART_RTL.
ARDUPILOT_MODES: tuple[ModeSpec, ...] = (
    ModeSpec("STABILIZE", 0, Behaviour.LEVEL, _STAB),
    ModeSpec("ACRO", 1, Behaviour.LEVEL, 0),
    ModeSpec("ALT_HOLD", 2, Behaviour.LEVEL, _STAB),
    ModeSpec("AUTO", 3, Behaviour.HOLD, _GUIDED | mavlink.MAV_MODE_FLAG_AUTO_ENABLED, armable=False),
    ModeSpec("GUIDED", 4, Behaviour.OFFBOARD, _GUIDED),
    ModeSpec("LOITER", 5, Behaviour.HOLD, _GUIDED),
    ModeSpec("RTL", 6, Behaviour.RTL, _GUIDED, armable=False),
    ModeSpec("CIRCLE", 7, Behaviour.HOLD, _GUIDED, armable=False),
    ModeSpec("LAND", 9, Behaviour.LAND, _STAB, armable=False),
    ModeSpec("POSHOLD", 16, Behaviour.HOLD, _GUIDED),
    ModeSpec("BRAKE", 17, Behaviour.BRAKE, _GUIDED, armable=False),
    ModeSpec("THROW", 18, Behaviour.HOLD, _STAB),
    ModeSpec("GUIDED_NOGPS", 20, Behaviour.OFFBOARD, _GUIDED),
    ModeSpec("SMART_RTL", 21, Behaviour.RTL, _GUIDED, armable=False),
)


class ParamType(enum.IntEnum):
    INT32 = mavlink.MAV_PARAM_TYPE_INT32
    REAL32 = mavlink.MAV_PARAM_TYPE_REAL32


@dataclass(frozen=True)
class ParamSpec:
    """A parameter: name (≤ 16 chars), default value, MAVLink type."""

    name: str
    default: float
    kind: ParamType = ParamType.REAL32


HOVER_PARAM: Mapping[str, str] = MappingProxyType({"px4": "MPC_THR_HOVER", "ardupilot": "MOT_THST_HOVER"})
# The parameter that switches the acceleration mapping's tilt between g alone (1) and the whole
# demand (0); ArduPilot has none (it always tilts from g alone).
ACCEL_DECOUPLE_PARAM = "MPC_ACC_DECOUPLE"
# The tilt limit of the acceleration path, as (parameter, degrees per unit), the first positive one
# ruling (PX4 MPC_TILTMAX_AIR deg; ArduPilot PSC_ANGLE_MAX deg unless 0, then ANGLE_MAX cdeg);
# each profile lists its own, set from the vehicle's tilt_max_rad.
TILT_LIMIT_PARAMS: Mapping[str, float] = MappingProxyType({"MPC_TILTMAX_AIR": 1.0, "PSC_ANGLE_MAX": 1.0, "ANGLE_MAX": 0.01})

PX4_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("COM_DISARM_LAND", 2.0),  # s, auto-disarm after landing
    ParamSpec("COM_DISARM_PRFLT", 10.0),  # s, auto-disarm if no takeoff after arming
    ParamSpec("COM_OBL_RC_ACT", 0, ParamType.INT32),  # offboard-loss action (0 pos → RTL w/o RC)
    ParamSpec("COM_OF_LOSS_T", 1.0),  # s, offboard signal timeout
    ParamSpec("COM_RC_IN_MODE", 1, ParamType.INT32),
    ParamSpec("MAV_SYS_ID", 1, ParamType.INT32),
    ParamSpec("MIS_TAKEOFF_ALT", 2.5),  # m
    ParamSpec("MPC_ACC_DECOUPLE", 1, ParamType.INT32),  # tilt from g alone (replaced by the vehicle's)
    ParamSpec("MPC_LAND_SPEED", 0.7),  # m/s
    ParamSpec("MPC_THR_HOVER", 0.5),  # 0..1, replaced by the vehicle's true hover thrust
    ParamSpec("MPC_TILTMAX_AIR", 45.0),  # deg, the acceleration path's tilt limit (replaced by the vehicle's)
    ParamSpec("MPC_TKO_SPEED", 1.5),  # m/s
    ParamSpec("MPC_XY_CRUISE", 5.0),  # m/s
    ParamSpec("MPC_Z_V_AUTO_DN", 1.5),  # m/s
    ParamSpec("MPC_Z_V_AUTO_UP", 3.0),  # m/s
    ParamSpec("RTL_RETURN_ALT", 30.0),  # m above home
    ParamSpec("SYS_AUTOSTART", 10040, ParamType.INT32),
)

ARDUPILOT_PARAMS: tuple[ParamSpec, ...] = (
    # ArduPilot's default is 1 (the collective sent with an attitude / rate target is divided by
    # cos(target tilt)); the mock flies the thrust as sent, and says so
    ParamSpec("ATC_ANGLE_BOOST", 0, ParamType.INT32),
    ParamSpec("ANGLE_MAX", 3000, ParamType.INT32),  # cdeg, lean angle limit (replaced by the vehicle's)
    ParamSpec("DISARM_DELAY", 10, ParamType.INT32),  # s, auto-disarm on the ground
    ParamSpec("FRAME_CLASS", 1, ParamType.INT32),
    ParamSpec("GUID_OPTIONS", 0, ParamType.INT32),
    ParamSpec("GUID_TIMEOUT", 3.0),  # s
    ParamSpec("LAND_SPEED", 50, ParamType.INT32),  # cm/s
    ParamSpec("PILOT_SPEED_UP", 250, ParamType.INT32),  # cm/s, the stick's full climb / descent in LOITER (PILOT_SPEED_DN 0)
    ParamSpec("MOT_THST_HOVER", 0.35),  # 0..1, replaced by the vehicle's true hover thrust
    ParamSpec("PSC_ANGLE_MAX", 0.0),  # deg, position controller's lean limit; 0: ANGLE_MAX
    ParamSpec("PSC_JERK_XY", 5.0),  # m/s^3
    ParamSpec("PSC_JERK_Z", 5.0),  # m/s^3
    ParamSpec("RTL_ALT", 1500, ParamType.INT32),  # cm
    ParamSpec("SYSID_THISMAV", 1, ParamType.INT32),
    ParamSpec("WPNAV_SPEED", 1000.0),  # cm/s
    ParamSpec("WPNAV_SPEED_DN", 150.0),  # cm/s
    ParamSpec("WPNAV_SPEED_UP", 250.0),  # cm/s
)

_M = mavlink
# Default streams (Hz, simulated time) of PX4 SITL's offboard-API link, as observed (see notes).
PX4_STREAMS: tuple[tuple[int, float], ...] = (
    (_M.MAVLINK_MSG_ID_HEARTBEAT, 1.0),
    (_M.MAVLINK_MSG_ID_ATTITUDE, 100.0),
    (_M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, 50.0),
    (_M.MAVLINK_MSG_ID_HIGHRES_IMU, 50.0),
    (_M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50.0),
    (_M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 30.0),
    (_M.MAVLINK_MSG_ID_ODOMETRY, 30.0),
    (_M.MAVLINK_MSG_ID_ATTITUDE_TARGET, 10.0),
    (_M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, 10.0),
    (_M.MAVLINK_MSG_ID_ALTITUDE, 10.0),
    (_M.MAVLINK_MSG_ID_VFR_HUD, 10.0),
    (_M.MAVLINK_MSG_ID_SYS_STATUS, 5.0),
    (_M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 5.0),
    (_M.MAVLINK_MSG_ID_HOME_POSITION, 0.5),
    (_M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0.1),  # PX4's mavlink_main.cpp streams it at 0.1 Hz
)
# ArduPilot SITL streams only HEARTBEAT until the client asks (SR*_ rates are 0 on the SITL link
# a client opens on 5760 before it requests streams).
ARDUPILOT_STREAMS: tuple[tuple[int, float], ...] = ((_M.MAVLINK_MSG_ID_HEARTBEAT, 1.0),)


@dataclass(frozen=True)
class Profile:
    """Everything that identifies one autopilot flavour."""

    name: str
    autopilot: int  # MAV_AUTOPILOT
    modes: tuple[ModeSpec, ...]
    params: tuple[ParamSpec, ...]
    streams: tuple[tuple[int, float], ...]
    initial_mode: str
    offboard_mode: str  # the mode that flies the client's setpoints
    hold_mode: str  # what a hover spawn / takeover defaults to
    takeoff_mode: str  # mode selected by NAV_TAKEOFF (PX4); ArduPilot takes off inside GUIDED
    land_mode: str
    rtl_mode: str
    max_rate_hz: float  # SET_MESSAGE_INTERVAL is capped here (and at the physics rate)
    capabilities: int

    def mode(self, name: str) -> ModeSpec:
        for spec in self.modes:
            if spec.name == name:
                return spec
        raise ValueError(f"mode: {name!r} is unknown for {self.name} (one of {[m.name for m in self.modes]})")

    def mode_by_custom(self, custom_mode: int) -> ModeSpec | None:
        for spec in self.modes:
            if spec.custom_mode == custom_mode:
                return spec
        return None

    @property
    def hover_param(self) -> str:
        return HOVER_PARAM[self.name]

    @property
    def bytewise_params(self) -> bool:
        """PX4 encodes INT32 params bytewise in param_value; ArduPilot casts to float."""
        return self.name == "px4"


_CAP = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)

PROFILES: Mapping[str, Profile] = MappingProxyType({
    "px4": Profile(
        name="px4",
        autopilot=mavlink.MAV_AUTOPILOT_PX4,
        modes=PX4_MODES,
        params=PX4_PARAMS,
        streams=PX4_STREAMS,
        initial_mode="AUTO.LOITER",
        offboard_mode="OFFBOARD",
        hold_mode="AUTO.LOITER",
        takeoff_mode="AUTO.TAKEOFF",
        land_mode="AUTO.LAND",
        rtl_mode="AUTO.RTL",
        max_rate_hz=250.0,
        capabilities=_CAP
        | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
    ),
    "ardupilot": Profile(
        name="ardupilot",
        autopilot=mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        modes=ARDUPILOT_MODES,
        params=ARDUPILOT_PARAMS,
        streams=ARDUPILOT_STREAMS,
        initial_mode="STABILIZE",
        offboard_mode="GUIDED",
        hold_mode="LOITER",
        takeoff_mode="GUIDED",
        land_mode="LAND",
        rtl_mode="RTL",
        max_rate_hz=250.0,
        capabilities=_CAP
        | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
    ),
})
