"""Invalid input: one clear ValueError naming the field; nothing invalid reaches the state."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from dynhelpers import make_sim

from sitl_mock.dynamics import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    CascadeGains,
    Gust,
    MotorsOff,
    PositionSetpoint,
    RateSetpoint,
    SensorNoise,
    Simulator,
    Spawn,
    Wind,
    preset,
)

NAN = float("nan")


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: AccelerationSetpoint((NAN, 0.0, 0.0)), "accel_ned_m_s2[0]"),
        (lambda: AccelerationSetpoint((0.0, 0.0, math.inf)), "accel_ned_m_s2[2]"),
        (lambda: AccelerationSetpoint((0.0, 0.0)), "accel_ned_m_s2"),
        (lambda: AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=NAN), "yaw_rad"),
        (lambda: AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rate_rad_s=NAN), "yaw_rate_rad_s"),
        (lambda: AttitudeSetpoint((NAN, 0.0, 0.0, 0.0), 0.5), "q_ned_frd[0]"),
        (lambda: AttitudeSetpoint((0.5, 0.0, 0.0, 0.0), 0.5), "q_ned_frd"),
        (lambda: AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), NAN), "thrust_norm"),
        (lambda: AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), 1.5), "thrust_norm"),
        (lambda: AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), -0.1), "thrust_norm"),
        (lambda: AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), 0.5, (0.0, NAN, 0.0)), "rates_ff_frd_rad_s[1]"),
        (lambda: RateSetpoint((0.0, 0.0, NAN), 0.5), "rates_frd_rad_s[2]"),
        (lambda: RateSetpoint((0.0, 0.0, 0.0), 2.0), "thrust_norm"),
        (lambda: PositionSetpoint((0.0, NAN, -1.0)), "position_ned_m[1]"),
        (lambda: PositionSetpoint((0.0, 0.0, -1.0), (NAN, 0.0, 0.0)), "velocity_ned_m_s[0]"),
        (lambda: PositionSetpoint((0.0, 0.0, -1.0), yaw_rad=math.inf), "yaw_rad"),
        (lambda: Spawn.hover((0.0, 0.0, NAN)), "position_ned_m[2]"),
        (lambda: Spawn.hover((0.0, 0.0, 1.0)), "position_ned_m[2]"),
        (lambda: Spawn.thrown((0.0, 0.0, -1.0), (NAN, 0.0, 0.0)), "velocity_ned_m_s[0]"),
        (lambda: Wind(mean_ned_m_s=(NAN, 0.0, 0.0)), "mean_ned_m_s[0]"),
        (lambda: Wind(turbulence_std_m_s=-1.0), "turbulence_std_m_s"),
        (lambda: Gust(0.0, 0.0, (1.0, 0.0, 0.0)), "duration_s"),
        (lambda: SensorNoise(delay_s=NAN), "delay_s"),
        (lambda: preset("fast").with_(mass_kg=-1.0), "mass_kg"),
        (lambda: preset("fast").with_(hover_thrust=NAN), "hover_thrust"),
        (lambda: preset("fast").with_(thrust_to_weight=0.9), "thrust_to_weight"),
        (lambda: preset("fast").with_(attitude_loop_hz=300.0), "attitude_loop_hz"),
        (lambda: preset("quadzilla"), "quadzilla"),
        (lambda: CascadeGains(1.0, NAN, 0.0, 0.0, 1.0), "rate_p_1_s"),
        (lambda: CascadeGains(1.0, 1.0, 0.0, -1.0, 1.0), "rate_d"),
        (lambda: CascadeGains(1.0, 1.0, 0.0, 0.0, 0.0), "rate_limit_rad_s"),
    ],
)
def test_invalid_values_raise_naming_the_field(build, field: str) -> None:
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace("]", r"\]")):
        build()


@pytest.mark.parametrize("dt", [NAN, math.inf, -0.001])
def test_invalid_dt_is_refused_and_state_untouched(dt: float) -> None:
    sim = make_sim("fast")
    before = sim.state()
    with pytest.raises(ValueError, match="dt_s"):
        sim.step(dt, MotorsOff())
    after = sim.state()
    np.testing.assert_array_equal(before.position_ned_m, after.position_ned_m)
    assert after.time_s == before.time_s


def test_unknown_setpoint_type_is_refused() -> None:
    sim = make_sim("fast")
    with pytest.raises(ValueError, match="setpoint"):
        sim.step(0.004, (0.0, 0.0, 0.0))  # type: ignore[arg-type]


def test_simulator_arguments_are_checked() -> None:
    with pytest.raises(ValueError, match="rng"):
        Simulator(preset("fast"), 42, Spawn.ground())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="params"):
        Simulator("fast", np.random.default_rng(0), Spawn.ground())  # type: ignore[arg-type]


def test_extreme_but_valid_setpoints_keep_the_state_finite() -> None:
    sim = make_sim("fast")
    setpoints = [
        AccelerationSetpoint((1e6, -1e6, -1e6), yaw_rad=1e3, yaw_rate_rad_s=1e3),
        AccelerationSetpoint((0.0, 0.0, 1e6)),
        AttitudeSetpoint((0.0, 1.0, 0.0, 0.0), 1.0, (1e3, -1e3, 1e3)),  # upside down, full thrust
        RateSetpoint((1e3, 1e3, -1e3), 1.0),
        PositionSetpoint((1e5, -1e5, -1e5), (1e3, 1e3, 1e3)),
    ]
    for sp in setpoints:
        for _ in range(50):
            s = sim.step(0.004, sp)
            for f in dataclasses.fields(s):
                v = getattr(s, f.name)
                assert np.all(np.isfinite(v)), f.name
        assert np.all(s.motor_thrust_n >= 0.0)
        assert np.all(s.motor_thrust_n <= sim.params.motor_thrust_max_n + 1e-12)


def test_state_is_immutable() -> None:
    s = make_sim("fast").step(0.004, MotorsOff())
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.landed = True  # type: ignore[misc]
    with pytest.raises(ValueError):
        s.position_ned_m[0] = 1.0


def test_setpoints_store_plain_float_tuples() -> None:
    sp = AccelerationSetpoint(np.array([1, 2, 3]))
    assert sp.accel_ned_m_s2 == (1.0, 2.0, 3.0) and all(type(v) is float for v in sp.accel_ned_m_s2)
    q = AttitudeSetpoint((1.001, 0.0, 0.0, 0.0), 0.5).q_ned_frd
    assert math.isclose(math.fsum(c * c for c in q), 1.0)  # small rounding is renormalised
