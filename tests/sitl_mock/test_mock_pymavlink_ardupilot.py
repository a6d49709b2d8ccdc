"""pymavlink ``mavutil`` against the ardupilot profile over TCP (ArduPilot SITL style)."""

from __future__ import annotations

import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import MockConfig
from sitl_mock.runner import run_in_thread

pytestmark = pytest.mark.integration


def _ack(conn, command: int, *params: float) -> int:
    values = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(1, 1, command, 0, *values)
    ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5, condition=f"COMMAND_ACK.command=={command}")
    assert ack is not None, f"no COMMAND_ACK for {command}"
    return ack.result


def _retry(mock, conn, command: int, *params: float, attempts: int = 50) -> int:
    """Repeat a command refused while the mock is not ready, letting 0.1 s of simulated time pass
    between attempts (not wall-clock time)."""
    for _ in range(attempts):
        result = _ack(conn, command, *params)
        if result == mavlink.MAV_RESULT_ACCEPTED:
            return result
        _sim_wait(mock, 0.1, conn)
    return result


def _sim_wait(mock, seconds: float, conn) -> None:
    t0 = mock.time_s
    deadline = time.monotonic() + 30
    while mock.time_s < t0 + seconds:
        assert time.monotonic() < deadline
        conn.recv_match(blocking=True, timeout=0.05)  # keep the client's buffer drained


def test_mavutil_guided_takeoff_and_setpoints() -> None:
    config = MockConfig(vehicle="fast", profile="ardupilot", udp_local_port=None, udp_remote=None, tcp_port=0, speed=5.0)
    with run_in_thread(config) as mock:
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{mock.ports.tcp}", source_system=255, source_component=190)
        try:
            hb = conn.wait_heartbeat(timeout=5)
            assert hb is not None and hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA and hb.type == 2
            # Only HEARTBEAT until asked, then LOCAL_POSITION_NED on request.
            assert conn.recv_match(type="ATTITUDE", blocking=True, timeout=0.3) is None
            assert _ack(conn, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 20000) == 0
            conn.param_set_send("GUID_OPTIONS", 8, mavlink.MAV_PARAM_TYPE_INT32)
            value = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
            assert value.param_id == "GUID_OPTIONS" and value.param_value == 8

            assert _retry(mock, conn, mavlink.MAV_CMD_DO_SET_MODE, 1, 4) == 0  # GUIDED once the EKF is ready
            conn.wait_heartbeat(timeout=5)
            assert mock.mock.autopilot.mode.name == "GUIDED"
            assert _ack(conn, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
            assert _ack(conn, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0) == 0
            _sim_wait(mock, 5.0, conn)
            assert mock.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.25)
            lpn = conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5)
            assert lpn.z == pytest.approx(-3.0, abs=0.3)

            # Velocity setpoint (type_mask: velocity only + yaw): fly north at 2 m/s.
            x0 = mock.truth.position_ned_m[0]
            for _ in range(20):
                conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0x0DC7, 0, 0, 0, 2.0, 0, 0, 0, 0, 0, 0, 0)
                _sim_wait(mock, 0.1, conn)
            assert mock.truth.velocity_ned_m_s[0] == pytest.approx(2.0, abs=0.4)
            assert mock.truth.position_ned_m[0] > x0 + 1.5

            # Acceleration only (type_mask 0x0C3F): 1.5 m/s² east; ArduPilot ramps it in (jerk limit).
            vy0, t0 = mock.truth.velocity_ned_m_s[1], mock.time_s
            for _ in range(20):
                conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0x0C3F, 0, 0, 0, 0, 0, 0, 0, 1.5, 0, 0, 0)
                _sim_wait(mock, 0.1, conn)
            dvy = mock.truth.velocity_ned_m_s[1] - vy0
            elapsed = mock.time_s - t0  # >= 2 s: each wait may overshoot by a wall-clock poll at 5x
            print(f"mavutil acceleration setpoint 1.5 m/s² east for {elapsed:.2f} s: velocity east +{dvy:.2f} m/s")
            assert 1.5 * elapsed - 0.5 < dvy < 1.5 * elapsed + 0.05  # 1.5 m/s² less the jerk-limited ramp-in

            # Body rates + thrust (attitude ignored, GUID_OPTIONS=8): yaw at 0.5 rad/s.
            hover = mock.mock.autopilot.sim.params.true_hover_thrust
            for _ in range(20):
                conn.mav.set_attitude_target_send(0, 1, 1, 0x80, [1, 0, 0, 0], 0, 0, 0.5, hover)
                _sim_wait(mock, 0.05, conn)
            assert mock.truth.rates_frd_rad_s[2] == pytest.approx(0.5, abs=0.05)

            # Attitude + raw thrust (GUID_OPTIONS=8): above hover thrust the vehicle climbs.
            z0 = mock.truth.position_ned_m[2]
            for _ in range(20):
                conn.mav.set_attitude_target_send(0, 1, 1, 0x07, [1, 0, 0, 0], 0, 0, 0, hover + 0.15)
                _sim_wait(mock, 0.05, conn)
            assert mock.truth.velocity_ned_m_s[2] < -1.0 and mock.truth.position_ned_m[2] < z0 - 0.3
        finally:
            conn.close()
