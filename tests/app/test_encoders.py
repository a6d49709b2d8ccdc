"""Encoders: frames, type masks, thrust normalisation, feed-forward honoured, NaN never sent."""

import math

import numpy as np
import pytest

from pf_offboard import frames
from pf_offboard.app.encoders import (
    ATTITUDE_IGNORE,
    G_M_S2,
    TYPE_MASK_ACCEL_YAW_YAWRATE,
    Encoder,
    attitude_rate_command,
    flown_when_tilting_from_gravity,
    thrust_normalised,
    tilt_from_gravity_setpoint,
)
from pf_offboard.app.estimator import StateEstimate
from pf_offboard.app.profiles import ARDUPILOT, PX4

from .helpers import command, quat_about


def estimate(q=(1.0, 0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0)) -> StateEstimate:
    return StateEstimate(12.5, np.zeros(3), np.asarray(velocity, float), np.asarray(q, float), np.zeros(3), 1)


def test_acceleration_setpoint_is_ned_with_yaw() -> None:
    enc = Encoder("acceleration", PX4, 1, 1, tilt_from_gravity=False)  # sent as computed
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
    acc = Encoder("acceleration", PX4, 1, 1, tilt_from_gravity=False).hold(est, 0).message
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
    k = G_M_S2 / (G_M_S2 + 0.1)  # ArduPilot tilts from g alone too (accel_to_lean_angles)
    assert (m.afx, m.afy, m.afz) == pytest.approx((-0.25 * k, 0.5 * k, -0.1))


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


def _px4_flies(accel_sent_enu) -> np.ndarray:
    """What the mock's PX4 acceleration mapping (PositionControl::_accelerationControl with
    MPC_ACC_DECOUPLE 1, the mock's code) makes the vehicle accelerate at, ENU, gravity excluded."""
    from sitl_mock.dynamics import Simulator, preset

    params = preset("px4-sih")
    params = params.with_(hover_thrust=params.true_hover_thrust)  # the autopilot knows its hover thrust
    sim = Simulator(params, np.random.default_rng(0))
    assert sim._accel_decouple
    q_ned_frd, thrust = sim._accel_to_attitude(tuple(frames.enu_to_ned(accel_sent_enu)), 0.0)
    w, x, y, z = q_ned_frd
    body_z_ned = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
    specific_force_ned = -thrust / params.true_hover_thrust * 9.80665 * body_z_ned
    return frames.ned_to_enu(specific_force_ned + np.array([0.0, 0.0, 9.80665]))


@pytest.mark.parametrize("accel_enu", [(1.5, -0.8, 1.5), (1.5, -0.8, -1.5), (-2.0, 0.5, 0.0), (0.3, 2.5, 3.0)])
def test_acceleration_setpoint_undoes_the_autopilots_tilt_from_gravity(accel_enu) -> None:
    """PX4 (MPC_ACC_DECOUPLE 1) tilts as if the vertical demand were zero: sent as computed, a
    climb's horizontal acceleration comes out (g + a_up) / g too large, a sink's too small. The
    encoder divides that out: what PX4's mapping flies is the acceleration the law asked for."""
    enc = Encoder("acceleration", PX4, 1, 1)
    assert enc.tilt_from_gravity and PX4.accel_tilt_from_gravity and ARDUPILOT.accel_tilt_from_gravity
    m = enc.encode(command(acceleration=accel_enu), estimate(), 0).message
    sent = frames.ned_to_enu([m.afx, m.afy, m.afz])
    assert _px4_flies(sent) == pytest.approx(accel_enu, abs=2e-3)  # g 9.81 against PX4's 9.80665
    naive = _px4_flies(accel_enu)
    if accel_enu[2] != 0.0:  # sent as computed, the horizontal part is off by a_up / g
        assert abs(naive[0] - accel_enu[0]) > 0.1 * abs(accel_enu[0]) * abs(accel_enu[2]) / 1.5
    assert sent[2] == pytest.approx(accel_enu[2])  # the vertical demand is sent as it is


def test_tilt_from_gravity_setpoint_and_its_inverse() -> None:
    for a in [(1.0, -2.0, 0.0), (1.0, -2.0, 2.5), (0.4, 0.1, -3.0)]:
        sent = tilt_from_gravity_setpoint(a)
        assert sent[:2] == pytest.approx(np.array(a[:2]) * G_M_S2 / (G_M_S2 + a[2]))
        assert flown_when_tilting_from_gravity(sent) == pytest.approx(a)
    # near free fall the divisor stops at g / 4: at most 4 x, the autopilot's tilt limit does the rest
    assert tilt_from_gravity_setpoint((1.0, 0.0, -9.0))[0] == pytest.approx(4.0)
    assert tilt_from_gravity_setpoint((1.0, 0.0, -50.0))[0] == pytest.approx(4.0)


def test_tilt_from_the_whole_demand_is_sent_as_computed_and_the_flag_survives_copies() -> None:
    """MPC_ACC_DECOUPLE 0 (read by fly): the autopilot tilts for the whole demand, nothing to undo."""
    enc = Encoder("acceleration", PX4, 1, 1).with_tilt_from_gravity(False)
    m = enc.encode(command(acceleration=(1.0, 2.0, 1.5)), estimate(), 0).message
    assert frames.ned_to_enu([m.afx, m.afy, m.afz]) == pytest.approx((1.0, 2.0, 1.5))
    assert not enc.with_hover_thrust(0.4).tilt_from_gravity  # hover thrust read later keeps it
    assert Encoder("rates", PX4, 1, 1).with_tilt_from_gravity(True).output_mode == "rates"
    # the hold in acceleration output is encoded the same way
    est = estimate(velocity=(1.0, 0.0, -1.0))  # sinking: the hold asks for +1 m/s^2 up
    hold = Encoder("acceleration", PX4, 1, 1).hold(est, 0).message
    a = frames.ned_to_enu([hold.afx, hold.afy, hold.afz])
    assert a[2] == pytest.approx(1.0)  # -1/s x velocity, below the 3 m/s^2 clip
    assert a[0] == pytest.approx(-1.0 * G_M_S2 / (G_M_S2 + 1.0))


def test_angle_boost_is_divided_out_in_attitude_and_rates() -> None:
    """ArduPilot (ATC_ANGLE_BOOST = 1) divides the thrust by cos(target tilt): the encoder sends the
    core's thrust times that cosine (attitude: the tilt sent; rates: the measured tilt, which the
    autopilot's integrated target follows); level setpoints and PX4 unchanged; copies keep it."""
    tilt = 0.4
    q = quat_about((1, 0, 0), tilt)
    cmd = command(attitude=q, thrust=12.0)
    plain = Encoder("attitude", ARDUPILOT, 1, 1, hover_thrust=0.4)
    boosted = plain.with_thrust_angle_boost(True)
    assert plain.encode(cmd, estimate(), 0).message.thrust == pytest.approx(12.0 / 9.81 * 0.4)
    assert boosted.encode(cmd, estimate(), 0).message.thrust == pytest.approx(12.0 / 9.81 * 0.4 * math.cos(tilt))
    assert boosted.with_hover_thrust(0.4).thrust_angle_boost and boosted.with_tilt_from_gravity(True).thrust_angle_boost
    level = command(attitude=(1.0, 0.0, 0.0, 0.0), thrust=12.0)
    assert boosted.encode(level, estimate(), 0).message.thrust == pytest.approx(12.0 / 9.81 * 0.4)
    rates = Encoder("rates", ARDUPILOT, 1, 1, hover_thrust=0.4, thrust_angle_boost=True)
    sent = rates.encode(cmd, estimate(q=q), 0).message.thrust  # at the target: projection 1
    assert sent == pytest.approx(12.0 / 9.81 * 0.4 * math.cos(tilt))
