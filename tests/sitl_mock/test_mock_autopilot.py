"""The autopilot state machine without sockets: modes, commands, params, failsafes, setpoints."""

from __future__ import annotations

import math
import struct
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.autopilot import Autopilot
from sitl_mock.config import FaultConfig, MockConfig, MockConfigError, SpawnSpec
from sitl_mock.dynamics import AttitudeSetpoint, MotorsOff, RateSetpoint
from sitl_mock.testing import accel_setpoint, command_long

DT = 0.004


def make(profile: str = "px4", **changes) -> Autopilot:
    ap = Autopilot(replace(MockConfig(vehicle="fast", profile=profile, ekf_ready_delay_s=0.2), **changes))
    ap.add_link(0)
    return ap


def cmd(ap: Autopilot, command: int, *params: float) -> int:
    replies = ap.handle(command_long(command, *params), 0)
    acks = [m for _, m in replies if m.get_type() == "COMMAND_ACK"]
    assert len(acks) == 1 and acks[0].command == command
    return acks[0].result


def guided_hover() -> Autopilot:
    """ArduCopter hovering at 10 m, handed over from LOITER into GUIDED (custom mode 4)."""
    ap = make("ardupilot", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    assert ap.mode.name == "LOITER"
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 4) == mavlink.MAV_RESULT_ACCEPTED
    return ap


def run(ap: Autopilot, seconds: float, msg=None, every: int = 5) -> None:
    """Step ``seconds`` of simulated time, sending ``msg`` every ``every`` steps (50 Hz)."""
    for i in range(int(round(seconds / DT))):
        if msg is not None and i % every == 0:
            ap.handle(msg, 0)
        ap.step(DT)


def param_value(ap: Autopilot, name: str) -> mavlink.MAVLink_message:
    replies = ap.handle(mavlink.MAVLink_param_request_read_message(1, 1, name.encode(), -1), 0)
    assert len(replies) == 1
    return replies[0][1]


def hover_px4_offboard(**changes) -> Autopilot:
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)), **changes)
    run(ap, 0.3)
    hold = accel_setpoint(0, 0, 0)
    run(ap, 0.2, hold)
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED
    return ap


# --------------------------------------------------------------------------------------------
# Identity and encodings
# --------------------------------------------------------------------------------------------


def test_heartbeat_identity_per_profile() -> None:
    px4 = make("px4").build(mavlink.MAVLINK_MSG_ID_HEARTBEAT)
    assert (px4.type, px4.autopilot) == (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4)
    assert px4.base_mode == 0x1D and px4.custom_mode == 50593792  # AUTO.LOITER, disarmed
    ap = make("ardupilot").build(mavlink.MAVLINK_MSG_ID_HEARTBEAT)
    assert (ap.type, ap.autopilot) == (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA)
    assert ap.custom_mode == 0 and not ap.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED  # STABILIZE


def test_px4_offboard_heartbeat_matches_observed_sitl() -> None:
    ap = hover_px4_offboard()
    hb = ap.build(mavlink.MAVLINK_MSG_ID_HEARTBEAT)
    assert hb.custom_mode == 393216 and hb.base_mode == 0x91 and hb.system_status == mavlink.MAV_STATE_ACTIVE


@pytest.mark.parametrize(
    ("main", "sub", "name", "custom"),
    [(4, 5, "AUTO.RTL", 84148224), (4, 3, "AUTO.LOITER", 50593792), (3, 0, "POSCTL", 3 << 16), (4, 6, "AUTO.LAND", 6 << 24 | 4 << 16)],
)
def test_px4_do_set_mode_custom_encoding(main: int, sub: int, name: str, custom: int) -> None:
    ap = make("px4")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, main, sub) == mavlink.MAV_RESULT_ACCEPTED
    assert ap.mode.name == name and ap.build(mavlink.MAVLINK_MSG_ID_HEARTBEAT).custom_mode == custom


def test_autopilot_version_capabilities() -> None:
    replies = make("px4").handle(command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION), 0)
    ack, version = replies[0][1], replies[1][1]
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED and version.get_type() == "AUTOPILOT_VERSION"
    for cap in (
        mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2,
        mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
        mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
        mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    ):
        assert version.capabilities & cap


def test_unknown_command_unsupported_and_other_targets_ignored() -> None:
    ap = make("px4")
    assert cmd(ap, 31000, 1) == mavlink.MAV_RESULT_UNSUPPORTED
    assert ap.handle(command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, target_system=7), 0) == []


def test_command_int_is_handled_like_command_long() -> None:
    ap = make("px4")
    run(ap, 0.3)
    msg = mavlink.MAVLink_command_int_message(1, 1, 0, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 1, 0, 0, 0, 0, 0, 0)
    assert ap.handle(msg, 0)[0][1].result == mavlink.MAV_RESULT_ACCEPTED and ap.armed


# --------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------


def test_param_list_and_required_names() -> None:
    for profile, names in (("px4", ("MPC_THR_HOVER", "COM_OF_LOSS_T", "COM_OBL_RC_ACT")),
                           ("ardupilot", ("MOT_THST_HOVER", "GUID_TIMEOUT", "GUID_OPTIONS"))):
        ap = make(profile)
        values = [m for _, m in ap.handle(mavlink.MAVLink_param_request_list_message(1, 1), 0)]
        ids = [m.param_id for m in values]
        assert all(name in ids for name in names)
        assert [m.param_index for m in values] == list(range(len(values)))
        assert all(m.param_count == len(values) for m in values)


def test_hover_param_is_the_vehicles_and_setting_it_reaches_the_dynamics() -> None:
    ap = make("px4")
    assert param_value(ap, "MPC_THR_HOVER").param_value == pytest.approx(ap.sim.params.hover_thrust)
    ap.handle(mavlink.MAVLink_param_set_message(1, 1, b"MPC_THR_HOVER", 0.4, mavlink.MAV_PARAM_TYPE_REAL32), 0)
    assert ap.sim.params.hover_thrust == pytest.approx(0.4)


def test_tilt_limit_param_is_the_vehicles_and_setting_it_clips_the_acceleration_path() -> None:
    """PX4 MPC_TILTMAX_AIR (deg) / ArduPilot ANGLE_MAX (cdeg; PSC_ANGLE_MAX 0 = use it) report the
    vehicle's tilt limit; setting one (PARAM_SET or MockConfig.params at start) moves the limit
    the acceleration path clips at; out of range: refused, unchanged."""
    px4 = make("px4")
    assert param_value(px4, "MPC_TILTMAX_AIR").param_value == pytest.approx(math.degrees(px4.sim.params.tilt_max_rad))
    px4.handle(mavlink.MAVLink_param_set_message(1, 1, b"MPC_TILTMAX_AIR", 30.0, mavlink.MAV_PARAM_TYPE_REAL32), 0)
    assert math.degrees(px4.sim.params.tilt_max_rad) == pytest.approx(30.0)
    px4.handle(mavlink.MAVLink_param_set_message(1, 1, b"MPC_TILTMAX_AIR", 95.0, mavlink.MAV_PARAM_TYPE_REAL32), 0)
    assert px4.params["MPC_TILTMAX_AIR"] == 30.0
    ap = make("ardupilot")
    assert (ap.params["PSC_ANGLE_MAX"], ap.params["ANGLE_MAX"]) == (0.0, round(100 * math.degrees(ap.sim.params.tilt_max_rad)))
    ap.handle(mavlink.MAVLink_param_set_message(1, 1, b"PSC_ANGLE_MAX", 20.0, mavlink.MAV_PARAM_TYPE_REAL32), 0)
    assert math.degrees(ap.sim.params.tilt_max_rad) == pytest.approx(20.0)
    ap.handle(mavlink.MAVLink_param_set_message(1, 1, b"PSC_ANGLE_MAX", 0.0, mavlink.MAV_PARAM_TYPE_REAL32), 0)
    assert math.degrees(ap.sim.params.tilt_max_rad) == pytest.approx(ap.params["ANGLE_MAX"] / 100.0)
    start = Autopilot(MockConfig(profile="px4", params=(("MPC_TILTMAX_AIR", 25.0),)))
    assert start.params["MPC_TILTMAX_AIR"] == 25.0 and math.degrees(start.sim.params.tilt_max_rad) == pytest.approx(25.0)
    with pytest.raises(MockConfigError, match="params"):
        Autopilot(MockConfig(profile="px4", params=(("MPC_TILTMAX_AIR", 0.0),)))
    with pytest.raises(MockConfigError, match=r"params\[0\]"):
        MockConfig(profile="px4", params=(("ANGLE_MAX", 3000.0),)).validate()


def test_int_params_bytewise_on_px4_and_cast_on_ardupilot() -> None:
    px4 = make("px4")
    wire = struct.unpack("<f", struct.pack("<i", 4))[0]
    reply = px4.handle(mavlink.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", wire, mavlink.MAV_PARAM_TYPE_INT32), 0)
    assert px4.params["COM_OBL_RC_ACT"] == 4
    assert struct.unpack("<i", struct.pack("<f", reply[0][1].param_value))[0] == 4
    ap = make("ardupilot")
    reply = ap.handle(mavlink.MAVLink_param_set_message(1, 1, b"GUID_OPTIONS", 8.0, mavlink.MAV_PARAM_TYPE_INT32), 0)
    assert ap.params["GUID_OPTIONS"] == 8 and reply[0][1].param_value == 8.0


# --------------------------------------------------------------------------------------------
# Arming
# --------------------------------------------------------------------------------------------


def test_arming_refused_until_position_estimate() -> None:
    ap = make("ardupilot", ekf_ready_delay_s=1.0)
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_FAILED
    assert any("Need Position Estimate" in e.text for e in ap.log)
    run(ap, 1.0)
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    px4 = make("px4", ekf_ready_delay_s=1.0)
    assert cmd(px4, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_ardupilot_refuses_arming_in_rtl_and_land() -> None:
    ap = make("ardupilot")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED  # RTL
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_FAILED
    assert not ap.armed


def test_disarm_refused_in_flight_unless_forced() -> None:
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -5.0)))
    run(ap, 0.5)
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) != mavlink.MAV_RESULT_ACCEPTED and ap.armed
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196) == mavlink.MAV_RESULT_ACCEPTED
    assert not ap.armed


def test_px4_auto_disarms_when_not_taking_off() -> None:
    ap = make("px4")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    run(ap, ap.params["COM_DISARM_PRFLT"] - 0.5)
    assert ap.armed
    run(ap, 1.0)
    assert not ap.armed


# --------------------------------------------------------------------------------------------
# PX4 OFFBOARD rules
# --------------------------------------------------------------------------------------------


def test_px4_offboard_refused_when_armed_without_setpoints_accepted_with_stream() -> None:
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    run(ap, 0.5)
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert ap.mode.name == "AUTO.LOITER"
    run(ap, 0.2, accel_setpoint(0, 0, 0))
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED
    assert ap.mode.name == "OFFBOARD"


def test_px4_offboard_accepted_while_disarmed_but_arming_then_needs_signal() -> None:
    ap = make("px4")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED  # as observed on SITL
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) != mavlink.MAV_RESULT_ACCEPTED
    run(ap, 0.2, accel_setpoint(0, 0, 0))
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED


@pytest.mark.parametrize(("action", "mode"), [(0, "AUTO.RTL"), (4, "AUTO.LAND"), (5, "AUTO.LOITER")])
def test_px4_offboard_loss_failsafe(action: int, mode: str) -> None:
    ap = hover_px4_offboard()
    ap.params["COM_OBL_RC_ACT"] = action
    run(ap, 0.9)  # within COM_OF_LOSS_T = 1 s of the last setpoint
    assert ap.mode.name == "OFFBOARD"
    run(ap, 0.4)
    assert ap.mode.name == mode and ap.failsafe
    assert ap.build(mavlink.MAVLINK_MSG_ID_HEARTBEAT).system_status == mavlink.MAV_STATE_CRITICAL


def test_px4_returns_to_offboard_when_setpoints_resume_unless_taken_over() -> None:
    ap = hover_px4_offboard()
    run(ap, 1.5)
    assert ap.mode.name == "AUTO.RTL"
    run(ap, 0.1, accel_setpoint(0, 0, 0))
    assert ap.mode.name == "OFFBOARD" and not ap.failsafe
    ap.inject_takeover("POSCTL")
    run(ap, 1.0, accel_setpoint(0, 0, -3.0))
    assert ap.mode.name == "POSCTL"
    assert abs(ap.truth.velocity_ned_m_s[2]) < 0.5  # the climb setpoint is ignored


def test_scheduled_takeover_ignores_offboard_setpoints() -> None:
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)), faults=FaultConfig(takeover_at_s=1.0))
    run(ap, 0.4, accel_setpoint(0, 0, 0))
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED
    run(ap, 1.5, accel_setpoint(2.0, 0, 0))
    assert ap.mode.name == "POSCTL"
    run(ap, 2.0, accel_setpoint(2.0, 0, 0))
    # Holding position (2 m/s² for 3.5 s would give 7 m/s).
    assert abs(ap.truth.velocity_ned_m_s[0]) < 0.5


def test_takeover_above_a_height_fires_once_in_the_climb() -> None:
    """takeover_above_m: the operator takes over the first time the vehicle is above 1 m over its
    spawn (a hover at 10 m climbing), not before, and only once; a timed takeover set later no longer fires."""
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)),
              faults=FaultConfig(takeover_above_m=1.0, takeover_at_s=30.0))  # fmt: skip
    run(ap, 0.4, accel_setpoint(0, 0, 0))
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED
    run(ap, 0.3, accel_setpoint(0, 0, -2.0))
    assert ap.mode.name == "OFFBOARD" and -ap.truth.position_ned_m[2] - 10.0 < 1.0
    run(ap, 2.0, accel_setpoint(0, 0, -2.0))
    assert ap.mode.name == "POSCTL"
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED  # back to OFFBOARD
    run(ap, 30.0, accel_setpoint(0, 0, 0))
    assert ap.mode.name == "OFFBOARD"  # fired once; the timed one was dropped with it


def test_takeover_above_m_is_validated() -> None:
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="faults.takeover_above_m"):
            FaultConfig(takeover_above_m=bad).validate()


# --------------------------------------------------------------------------------------------
# Setpoint semantics
# --------------------------------------------------------------------------------------------


def test_px4_acceleration_setpoint_moves_the_vehicle() -> None:
    ap = hover_px4_offboard()
    run(ap, 1.0, accel_setpoint(1.0, 0.0, 0.0))
    assert ap.truth.velocity_ned_m_s[0] == pytest.approx(0.9, abs=0.25)


def _attitude(mask: int, q=(1.0, 0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), thrust: float = 0.5):
    return mavlink.MAVLink_set_attitude_target_message(0, 1, 1, mask, list(q), *rates, thrust)


def test_px4_quaternion_uses_only_yaw_rate_feedforward() -> None:
    ap = hover_px4_offboard()
    run(ap, 0.1, _attitude(0, rates=(1.0, 1.0, 0.3), thrust=0.3))
    sp = ap._dyn_setpoint
    assert isinstance(sp, AttitudeSetpoint) and sp.rates_ff_frd_rad_s == (0.0, 0.0, 0.3)


def test_px4_rates_and_throttle_ignore() -> None:
    ap = hover_px4_offboard()
    run(ap, 0.1, _attitude(0x80, rates=(0.0, 0.0, 0.5), thrust=0.3))
    assert isinstance(ap._dyn_setpoint, RateSetpoint) and ap._dyn_setpoint.thrust_norm == 0.3
    run(ap, 0.5, _attitude(0x80 | 0x40, thrust=0.3))
    assert ap._dyn_setpoint.thrust_norm == 0.0
    assert ap.truth.velocity_ned_m_s[2] > 2.0  # falling


@pytest.mark.parametrize(
    "bad",
    [
        _attitude(0, q=(math.nan, 0, 0, 0)),
        _attitude(0, q=(0, 0, 0, 0)),
        _attitude(0, thrust=math.inf),
        _attitude(0x80 | 0x02),  # attitude ignored, pitch rate missing
        accel_setpoint(math.inf, 0, 0),
        mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, mavlink.MAV_FRAME_GLOBAL_INT, 0x0C3F, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0),
    ],
)
def test_px4_bad_setpoints_are_ignored(bad) -> None:
    ap = hover_px4_offboard()
    before = ap._dyn_setpoint
    ap.handle(bad, 0)
    ap.step(DT)
    assert type(ap._dyn_setpoint) is type(before)
    assert np.all(np.isfinite(ap.truth.position_ned_m))
    assert any("ignored" in e.text for e in ap.log)


def test_px4_thrown_spawn_is_ballistic_until_commanded() -> None:
    p0, v0 = np.array([0.0, 0.0, -20.0]), np.array([3.0, 1.0, -4.0])
    ap = make("px4", spawn=SpawnSpec("throw", tuple(p0), tuple(v0)))
    run(ap, 1.0)
    k, g, t = ap.sim.params.drag_1_s, 9.80665, ap.time_s
    decay = (1 - math.exp(-k * t)) / k
    expected = p0 + v0 * decay + np.array([0, 0, g]) * (t - decay) / k  # linear drag, no wind
    assert isinstance(ap._dyn_setpoint, MotorsOff)
    np.testing.assert_allclose(ap.truth.position_ned_m, expected, atol=0.02)
    # Commanded: stream setpoints, switch to OFFBOARD, the vehicle stops falling.
    run(ap, 0.1, accel_setpoint(0, 0, 0))
    assert isinstance(ap._dyn_setpoint, MotorsOff)  # setpoints alone do not unlock the motors
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6) == mavlink.MAV_RESULT_ACCEPTED
    v_switch = ap.truth.velocity_ned_m_s[2]
    run(ap, 2.0, accel_setpoint(0, 0, -2.0))  # 2 m/s² upward
    assert ap.truth.velocity_ned_m_s[2] < v_switch - 3.5  # commanded 4 m/s (+ drag), minus spin-up


def test_ardupilot_accel_zero_keeps_velocity_px4_drifts_with_drag() -> None:
    results = {}
    for profile in ("px4", "ardupilot"):
        ap = make(profile, spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
        run(ap, 0.3, accel_setpoint(0, 0, 0))
        # Hover spawns hold (AUTO.LOITER / LOITER); switch to OFFBOARD (6) / GUIDED (4) as a client must.
        assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 6 if profile == "px4" else 4) == mavlink.MAV_RESULT_ACCEPTED
        run(ap, 1.5, accel_setpoint(2.0, 0, 0, yaw=0.0))
        run(ap, 1.0, accel_setpoint(0, 0, 0, yaw=0.0))  # ArduPilot: jerk-limited ramp down, settle
        v_start = ap.truth.velocity_ned_m_s[0]
        run(ap, 2.0, accel_setpoint(0, 0, 0, yaw=0.0))
        results[profile] = (v_start, ap.truth.velocity_ned_m_s[0])
    v0, v1 = results["ardupilot"]
    assert v0 > 2.0 and v1 == pytest.approx(v0, rel=0.05)
    p0, p1 = results["px4"]
    assert p1 < 0.8 * p0  # open loop: drag decelerates it


def test_ardupilot_guid_options_16_32_stop_xy_correction() -> None:
    ap = guided_hover()
    ap.params["GUID_OPTIONS"] = 32
    run(ap, 0.3, accel_setpoint(0, 0, 0, yaw=0.0))
    run(ap, 1.5, accel_setpoint(2.0, 0, 0, yaw=0.0))
    v0 = ap.truth.velocity_ned_m_s[0]
    run(ap, 3.0, accel_setpoint(0, 0, 0, yaw=0.0))
    assert ap.truth.velocity_ned_m_s[0] < 0.8 * v0  # no velocity stabilisation: drag wins


def test_ardupilot_guided_timeout_brakes_to_hover() -> None:
    ap = guided_hover()
    run(ap, 1.5, accel_setpoint(2.0, 0, 0, yaw=0.0))
    assert ap.truth.velocity_ned_m_s[0] > 1.5
    run(ap, ap.params["GUID_TIMEOUT"] - 0.2)
    assert ap.guided.submode == "accel" and ap.truth.velocity_ned_m_s[0] > 1.5  # holds the last command
    run(ap, 4.0)
    assert ap.mode.name == "GUIDED" and abs(ap.truth.velocity_ned_m_s[0]) < 0.3


def test_ardupilot_attitude_thrust_is_climb_rate_unless_option_8() -> None:
    ap = guided_hover()
    run(ap, 2.0, _attitude(0x07, thrust=0.5))
    assert abs(ap.truth.velocity_ned_m_s[2]) < 0.1  # 0.5 holds altitude
    run(ap, 2.0, _attitude(0x07, thrust=0.9))
    assert ap.truth.velocity_ned_m_s[2] == pytest.approx(-0.4 * 2 * 2.5, abs=0.2)  # climb at 2 m/s
    ap.params["GUID_OPTIONS"] = 8
    hover = ap.sim.params.true_hover_thrust
    run(ap, 1.0, _attitude(0x07, thrust=hover + 0.2))
    assert ap._dyn_setpoint.thrust_norm == pytest.approx(hover + 0.2)


def test_ardupilot_malformed_attitude_brakes_and_masked_thrust_is_ignored() -> None:
    ap = guided_hover()
    run(ap, 0.5, _attitude(0x07, thrust=0.7))
    assert ap.guided.submode == "angle"
    ap.handle(_attitude(0x40, thrust=0.7), 0)
    assert ap.guided.angle.thrust > 0 and any("THROTTLE_IGNORE" in e.text for e in ap.log)
    ap.handle(_attitude(0x07, q=(0.9, 0, 0, 0)), 0)  # non-unit quaternion
    assert ap.guided.submode == "hold"
    ap.handle(_attitude(0x06, rates=(1.0, 0, 0)), 0)  # partial rates
    assert ap.guided.submode == "hold"


def test_ardupilot_rejects_position_plus_accel_without_velocity() -> None:
    ap = guided_hover()
    mask = 0x0C38  # position + acceleration, velocity ignored, yaw ignored
    msg = mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, mask, 5, 0, -10, 0, 0, 0, 1, 0, 0, 0, 0)
    ap.handle(msg, 0)
    assert any("not a supported combination" in e.text for e in ap.log)


def test_ardupilot_guided_takeoff_then_position_target() -> None:
    ap = make("ardupilot")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0) == mavlink.MAV_RESULT_FAILED  # not GUIDED
    assert cmd(ap, mavlink.MAV_CMD_DO_SET_MODE, 1, 4) == mavlink.MAV_RESULT_ACCEPTED
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert cmd(ap, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0) == mavlink.MAV_RESULT_ACCEPTED
    run(ap, 5.0)
    assert ap.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.2)
    target = mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0x0DF8, 4.0, 0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0)
    run(ap, 6.0, target)
    np.testing.assert_allclose(ap.truth.position_ned_m, [4.0, 0.0, -3.0], atol=0.2)


def test_px4_takeoff_then_land_disarms() -> None:
    ap = make("px4")
    run(ap, 0.3)
    assert cmd(ap, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert cmd(ap, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + 3.0) == 0
    run(ap, 5.0)
    assert ap.mode.name == "AUTO.LOITER" and ap.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.3)
    assert cmd(ap, mavlink.MAV_CMD_NAV_LAND) == mavlink.MAV_RESULT_ACCEPTED
    run(ap, 8.0)
    assert ap.truth.landed and not ap.armed


def test_estimator_reset_jumps_estimate_not_vehicle() -> None:
    ap = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)), faults=FaultConfig(estimator_reset_at_s=0.5))
    odo0 = ap.build(mavlink.MAVLINK_MSG_ID_ODOMETRY)
    run(ap, 1.0)
    odo1 = ap.build(mavlink.MAVLINK_MSG_ID_ODOMETRY)
    lpn = ap.build(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
    assert odo1.reset_counter == odo0.reset_counter + 1
    assert lpn.x == pytest.approx(ap.truth.position_ned_m[0] + 2.0, abs=1e-6)
    assert lpn.y == pytest.approx(ap.truth.position_ned_m[1] - 1.0, abs=1e-6)
    assert np.linalg.norm(ap.truth.position_ned_m[:2]) < 0.05  # the hold target moved with the estimate


def test_odometry_frames_like_px4() -> None:
    ap = make("px4", spawn=SpawnSpec("throw", (0.0, 0.0, -20.0), (3.0, 1.0, 0.0)))
    run(ap, 0.2)
    odo = ap.build(mavlink.MAVLINK_MSG_ID_ODOMETRY)
    assert (odo.frame_id, odo.child_frame_id) == (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED)
    np.testing.assert_allclose([odo.vx, odo.vy, odo.vz], ap.truth.velocity_ned_m_s, atol=1e-5)  # NED velocity


def test_scheduled_wind_gust_pushes_the_hovering_vehicle() -> None:
    calm = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    gusty = make("px4", spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)),
                 faults=FaultConfig(gust_at_s=0.5, gust_ned_m_s=(8.0, 0.0, 0.0), gust_duration_s=2.0))
    run(calm, 2.0)
    run(gusty, 2.0)
    assert abs(calm.truth.position_ned_m[0]) < 0.02
    assert gusty.truth.position_ned_m[0] > 0.1  # blown north, the hold controller fights back


def test_ardupilot_request_data_stream_groups() -> None:
    ap = make("ardupilot")
    run(ap, 0.3)
    ap.handle(mavlink.MAVLink_request_data_stream_message(1, 1, mavlink.MAV_DATA_STREAM_EXTRA1, 25, 1), 0)
    ap.due_telemetry()
    sent = []
    for _ in range(250):  # 1 s
        ap.step(DT)
        sent += [m.get_type() for _, m in ap.due_telemetry()]
    assert sent.count("ATTITUDE") == 25 and sent.count("HEARTBEAT") == 1
    ap.handle(mavlink.MAVLink_request_data_stream_message(1, 1, mavlink.MAV_DATA_STREAM_ALL, 0, 0), 0)
    run(ap, 1.0)
    assert mavlink.MAVLINK_MSG_ID_ATTITUDE not in ap.streams[0].streams
    assert make("px4").handle(mavlink.MAVLink_request_data_stream_message(1, 1, 0, 10, 1), 0) == []
