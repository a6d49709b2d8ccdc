"""Setpoint decoding per autopilot: frames, type_mask combinations, NaN/inf handling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.setpoints import (
    AttitudeTarget,
    BrakeAndHover,
    Rejected,
    TrajectoryTarget,
    ardupilot_attitude_target,
    ardupilot_position_target,
    px4_attitude_target,
    px4_position_target,
)

HERE = np.array([10.0, 20.0, -5.0])
YAW = math.pi / 2  # facing east


def spt(frame: int, mask: int, pos=(0, 0, 0), vel=(0, 0, 0), acc=(0, 0, 0), yaw=0.0, yaw_rate=0.0):
    return mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, *pos, *vel, *acc, yaw, yaw_rate)


def sat(mask: int, q=(1.0, 0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), thrust=0.5):
    return mavlink.MAVLink_set_attitude_target_message(0, 1, 1, mask, list(q), *rates, thrust)


def test_px4_accel_only_and_per_axis_nan() -> None:
    t = px4_position_target(spt(1, 0x0C3F, acc=(1, 2, 3)), HERE, YAW)
    assert isinstance(t, TrajectoryTarget) and t.kind == "accel" and t.accel_ned_m_s2 == (1, 2, 3)
    assert math.isnan(t.yaw_rad) and math.isnan(t.yaw_rate_rad_s)
    t = px4_position_target(spt(1, 0x0DFB, pos=(0, 0, -7)), HERE, YAW)  # z position only
    assert t.kind == "pvt" and math.isnan(t.position_ned_m[0]) and t.position_ned_m[2] == -7


def test_px4_body_ned_is_rotated_by_yaw_and_offset_by_position() -> None:
    t = px4_position_target(spt(mavlink.MAV_FRAME_BODY_NED, 0x09F8, pos=(1, 0, 0)), HERE, YAW)
    np.testing.assert_allclose(t.position_ned_m, HERE + [0.0, 1.0, 0.0], atol=1e-9)  # 1 m ahead = east
    t = px4_position_target(spt(mavlink.MAV_FRAME_BODY_NED, 0x0C3F, acc=(2, 0, 0)), HERE, YAW)
    np.testing.assert_allclose(t.accel_ned_m_s2, [0.0, 2.0, 0.0], atol=1e-9)


@pytest.mark.parametrize(
    ("msg", "reason"),
    [
        (spt(mavlink.MAV_FRAME_LOCAL_OFFSET_NED, 0x0C3F), "coordinate_frame"),
        (spt(1, 0x0C3F | mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET), "FORCE_SET"),
        (spt(1, 0x0C3F, acc=(math.inf, 0, 0)), "infinite"),
        (spt(1, 0x0DFF), "no position"),  # everything ignored (FORCE_SET clear)
        (spt(1, 0x0C3F, acc=(math.nan, 0, 0)), "no position"),  # NaN = ignored: nothing complete left
    ],
)
def test_px4_rejections(msg, reason: str) -> None:
    result = px4_position_target(msg, HERE, YAW)
    assert isinstance(result, Rejected) and reason in result.reason


@pytest.mark.parametrize(
    ("mask", "kind"),
    [(0x0DF8, "pos"), (0x0DC7, "velaccel"), (0x0C07, "velaccel"), (0x0C3F, "accel"), (0x0DC0, "posvelaccel")],
)
def test_ardupilot_combinations(mask: int, kind: str) -> None:
    t = ardupilot_position_target(spt(1, mask, pos=(1, 2, -3), vel=(1, 0, 0), acc=(0, 1, 0)), HERE, YAW)
    assert isinstance(t, TrajectoryTarget) and t.kind == kind


def test_ardupilot_offset_and_body_frames() -> None:
    t = ardupilot_position_target(spt(mavlink.MAV_FRAME_LOCAL_OFFSET_NED, 0x0DF8, pos=(1, 0, 0)), HERE, YAW)
    np.testing.assert_allclose(t.position_ned_m, HERE + [1.0, 0.0, 0.0])
    t = ardupilot_position_target(spt(mavlink.MAV_FRAME_BODY_OFFSET_NED, 0x09F8, pos=(1, 0, 0), yaw=0.1), HERE, YAW)
    np.testing.assert_allclose(t.position_ned_m, HERE + [0.0, 1.0, 0.0], atol=1e-9)
    assert t.yaw_rad == pytest.approx(YAW + 0.1)  # body frames: yaw relative to the heading
    t = ardupilot_position_target(spt(mavlink.MAV_FRAME_BODY_NED, 0x0DC7, vel=(2, 0, 0)), HERE, YAW)
    np.testing.assert_allclose(t.velocity_ned_m_s, [0.0, 2.0, 0.0], atol=1e-9)


def test_ardupilot_rejects_nan_in_used_fields() -> None:
    assert isinstance(ardupilot_position_target(spt(1, 0x0C3F, acc=(math.nan, 0, 0)), HERE, YAW), Rejected)
    assert isinstance(ardupilot_position_target(spt(mavlink.MAV_FRAME_GLOBAL, 0x0C3F), HERE, YAW), Rejected)


def test_px4_attitude_variants() -> None:
    q = (math.cos(0.1), math.sin(0.1), 0.0, 0.0)
    t = px4_attitude_target(sat(0, q=tuple(2 * c for c in q), rates=(1, 1, 0.2), thrust=1.5))
    assert isinstance(t, AttitudeTarget)
    np.testing.assert_allclose(t.q_ned_frd, q)  # normalised
    assert t.rates_frd_rad_s == (0.0, 0.0, 0.2) and t.thrust == 1.0  # yaw FF only, thrust clamped
    t = px4_attitude_target(sat(0x80 | 0x04, rates=(0.1, 0.2, 0.3), thrust=0.4))
    assert t.q_ned_frd is None and t.rates_frd_rad_s == (0.1, 0.2, 0.0)  # yaw rate ignored → 0


def test_ardupilot_attitude_thrust_and_rates() -> None:
    t = ardupilot_attitude_target(sat(0x07, thrust=0.75), False, 2.5, 1.5)
    assert t.thrust_is_climb_rate and t.thrust == pytest.approx(1.25)
    t = ardupilot_attitude_target(sat(0x07, thrust=0.0), False, 2.5, 1.5)
    assert t.thrust == pytest.approx(-1.5)
    t = ardupilot_attitude_target(sat(0x00, rates=(0.1, 0.2, 0.3), thrust=0.4), True, 2.5, 1.5)
    assert not t.thrust_is_climb_rate and t.thrust == 0.4 and t.rates_frd_rad_s == (0.1, 0.2, 0.3)
    assert isinstance(ardupilot_attitude_target(sat(0x40), True, 2.5, 1.5), Rejected)
    assert isinstance(ardupilot_attitude_target(sat(0x07, q=(0.5, 0, 0, 0)), True, 2.5, 1.5), BrakeAndHover)
    assert isinstance(ardupilot_attitude_target(sat(0x01), True, 2.5, 1.5), BrakeAndHover)
