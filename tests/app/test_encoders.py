"""Encoders: frames, type masks, thrust normalisation, feed-forward honoured, NaN never sent."""

import math

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.app.encoders import (
    ATTITUDE_IGNORE,
    TYPE_MASK_ACCEL_YAW_YAWRATE,
    Encoder,
    attitude_rate_command,
    thrust_normalised,
)
from pf_offboard.app.estimator import StateEstimate
from pf_offboard.app.profiles import ARDUPILOT, PX4

from .helpers import command, quat_about


def estimate(q=(1.0, 0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0)) -> StateEstimate:
    return StateEstimate(12.5, np.zeros(3), np.asarray(velocity, float), np.asarray(q, float), np.zeros(3), 1)


def test_acceleration_setpoint_is_ned_with_yaw() -> None:
    enc = Encoder("acceleration", PX4, 1, 1)
    out = enc.encode(command(), estimate(), 12500)
    m = out.message
    assert m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert (m.coordinate_frame, m.type_mask) == (1, TYPE_MASK_ACCEL_YAW_YAWRATE) == (1, 0x03F)
    assert (m.afx, m.afy, m.afz) == pytest.approx((-0.25, 0.5, -0.1))  # ENU (e, n, u) -> NED (n, e, -u)
    assert m.yaw == pytest.approx(math.pi / 2 - 0.3)
    assert m.yaw_rate == pytest.approx(-0.05)
    assert (m.target_system, m.target_component, m.time_boot_ms) == (1, 1, 12500)
    assert not out.replaced


def test_thrust_normalisation() -> None:
    assert thrust_normalised(9.81, 0.37) == pytest.approx(0.37)
    assert thrust_normalised(2 * 9.81, 0.5) == pytest.approx(1.0)
    assert thrust_normalised(50.0, 0.5) == 1.0  # clipped
    assert thrust_normalised(-1.0, 0.5) == 0.0


def test_attitude_px4_sends_only_yaw_rate_feed_forward() -> None:
    q_des = quat_about((1, 1, 0), 0.3)
    cmd = command(attitude=q_des, body_rates=(0.1, -0.2, 0.3), thrust=12.0)
    out = Encoder("attitude", PX4, 1, 1, hover_thrust=0.4).encode(cmd, estimate(), 0)
    m = out.message
    assert m.type_mask == 0b011  # roll and pitch rate ignored: PX4 drops them next to a quaternion
    assert (m.body_roll_rate, m.body_pitch_rate) == (0.0, 0.0)
    assert m.body_yaw_rate == pytest.approx(-0.3)  # FLU z up -> FRD z down
    assert list(m.q) == pytest.approx(list(frames.quat_enu_flu_to_ned_frd(q_des)), abs=1e-7)
    assert m.thrust == pytest.approx(12.0 / 9.81 * 0.4)


def test_attitude_ardupilot_sends_all_rates() -> None:
    out = Encoder("attitude", ARDUPILOT, 1, 1, hover_thrust=0.37).encode(command(body_rates=(0.1, -0.2, 0.3)), estimate(), 0)
    m = out.message
    assert m.type_mask == 0
    assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == pytest.approx((0.1, 0.2, -0.3))


def test_rates_mode_feed_forward_at_zero_error() -> None:
    q = quat_about((0, 0, 1), 0.7)
    cmd = command(attitude=q, body_rates=(0.1, -0.2, 0.3), thrust=9.81)
    out = Encoder("rates", PX4, 1, 1, hover_thrust=0.5).encode(cmd, estimate(q=q), 0)
    m = out.message
    assert m.type_mask == ATTITUDE_IGNORE
    assert (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate) == pytest.approx((0.1, 0.2, -0.3))
    assert m.thrust == pytest.approx(0.5)


def test_rates_mode_corrects_attitude_error_with_time_constant() -> None:
    # desired is rolled +0.1 rad (FLU x) from the measured attitude: the rate command rolls that way
    q_meas = quat_about((0, 0, 1), 0.4)
    q_des = frames.quat_multiply(q_meas, quat_about((1, 0, 0), 0.1))
    w = attitude_rate_command(q_des, q_meas, np.zeros(3), time_constant_s=0.2)
    assert w == pytest.approx([2.0 / 0.2 * math.sin(0.05), 0.0, 0.0], abs=1e-12)
    # shortest way round: q and -q give the same command
    assert attitude_rate_command(-q_des, q_meas, np.zeros(3), 0.2) == pytest.approx(w)
    # thrust projected on the current body axis: tilted 0.1 rad off the demand, cos(0.1) of it
    out = Encoder("rates", PX4, 1, 1, hover_thrust=0.5, time_constant_s=0.2).encode(
        command(attitude=q_des, body_rates=(0, 0, 0), thrust=9.81), estimate(q=q_meas), 0
    )
    assert out.message.thrust == pytest.approx(0.5 * math.cos(0.1))
    assert out.message.body_roll_rate == pytest.approx(w[0])  # FLU x == FRD x


@pytest.mark.parametrize("mode", ["acceleration", "attitude", "rates"])
@pytest.mark.parametrize("field", ["acceleration", "thrust", "attitude", "body_rates", "yaw", "yaw_rate"])
def test_nan_never_goes_out(mode: str, field: str) -> None:
    bad = {
        "acceleration": (math.nan, 0.0, 0.0),
        "thrust": math.nan,
        "attitude": (math.nan, 0.0, 0.0, 1.0),
        "body_rates": (0.0, math.inf, 0.0),
        "yaw": math.nan,
        "yaw_rate": math.inf,
    }[field]
    enc = Encoder(mode, PX4, 1, 1)
    out = enc.encode(command(**{field: bad}), estimate(velocity=(1.0, 0.0, 0.0)), 0)
    values = [getattr(out.message, n) for n in out.message.get_fieldnames()]
    flat = [float(x) for v in values for x in (v if isinstance(v, list) else [v]) if isinstance(x, (int, float))]
    assert all(math.isfinite(x) for x in flat)
    assert out.replaced, "a non-finite command field means the core failed: the hold goes out"


def test_hold_setpoints() -> None:
    est = estimate(q=quat_about((0, 0, 1), 0.5), velocity=(2.0, 0.0, -10.0))
    acc = Encoder("acceleration", PX4, 1, 1).hold(est, 0).message
    a_enu = frames.ned_to_enu([acc.afx, acc.afy, acc.afz])
    assert np.linalg.norm(a_enu) == pytest.approx(3.0)  # damping, clipped to 3 m/s^2
    assert np.dot(a_enu, [2.0, 0.0, -10.0]) < 0  # opposes the motion
    att = Encoder("attitude", PX4, 1, 1, hover_thrust=0.42).hold(est, 0).message
    assert att.thrust == pytest.approx(0.42)
    assert list(att.q) == pytest.approx(list(frames.quat_enu_flu_to_ned_frd(quat_about((0, 0, 1), 0.5))), abs=1e-7)


def test_ardupilot_acceleration_carries_the_measured_velocity() -> None:
    out = Encoder("acceleration", ARDUPILOT, 1, 1).encode(command(), estimate(velocity=(1.0, 2.0, -0.5)), 0)
    m = out.message
    assert m.type_mask == 0x007  # velocity + acceleration + yaw + yaw rate
    assert (m.vx, m.vy, m.vz) == pytest.approx((2.0, 1.0, 0.5))  # ENU -> NED
    assert (m.afx, m.afy, m.afz) == pytest.approx((-0.25, 0.5, -0.1))


def test_with_hover_thrust_keeps_everything_else_and_validates() -> None:
    enc = Encoder("rates", ARDUPILOT, 3, 7, hover_thrust=0.5, time_constant_s=0.05)
    new = enc.with_hover_thrust(0.37)
    assert (new.output_mode, new.profile, new.target_system, new.target_component) == ("rates", ARDUPILOT, 3, 7)
    assert (new.hover_thrust, new.time_constant_s) == (0.37, 0.05)
    assert enc.hover_thrust == 0.5  # a copy: the original is untouched
    cmd = command(thrust=9.81)
    assert new.encode(cmd, estimate(), 0).message.thrust == pytest.approx(0.37, rel=1e-6)
    with pytest.raises(ValueError, match="hover_thrust"):
        enc.with_hover_thrust(1.5)
