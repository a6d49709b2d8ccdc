"""BatchSimulator against the scalar sitl_mock Simulator, at run time: thrown vehicles with wind
and spin under every setpoint kind (acceleration with and without yaw, attitude with and without
the rate feed-forward, rates, the position hold), on the two realistic presets, through touchdowns
and crashes, with the estimator's error drawn from each vehicle's own generator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sitl_mock.dynamics import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    MotorsOff,
    PositionSetpoint,
    RateSetpoint,
    Simulator,
    Spawn,
    Wind,
    euler_to_quat,
    preset,
)

from pf_offboard.sim.batch.dynamics import ACCEL, ATTITUDE, MOTORS_OFF, POSITION, RATES, BatchSetpoint, BatchSimulator

KINDS = (ACCEL, ATTITUDE, RATES, POSITION)


def _scalar_setpoint(sp: BatchSetpoint, i: int):  # type: ignore[no-untyped-def]
    kind = sp.kind[i]
    if kind == MOTORS_OFF:
        return MotorsOff()
    if kind == ACCEL:
        yaw = None if math.isnan(sp.yaw_rad[i]) else float(sp.yaw_rad[i])
        return AccelerationSetpoint(tuple(sp.accel_ned_m_s2[:, i]), yaw, float(sp.yaw_rate_rad_s[i]))
    if kind == ATTITUDE:
        return AttitudeSetpoint(tuple(sp.q_ned_frd[:, i]), float(sp.thrust_norm[i]), tuple(sp.rates_frd_rad_s[:, i]) if sp.has_ff[i] else None)
    if kind == RATES:
        return RateSetpoint(tuple(sp.rates_frd_rad_s[:, i]), float(sp.thrust_norm[i]))
    yaw = None if math.isnan(sp.yaw_rad[i]) else float(sp.yaw_rad[i])
    assert sp.position_ned_m is not None
    return PositionSetpoint(tuple(sp.position_ned_m[:, i]), (0.0, 0.0, 0.0), yaw)


@pytest.mark.parametrize("vehicle", ["px4-sih", "arducopter"])
def test_the_batch_flies_every_vehicle_as_the_scalar_simulator(vehicle: str) -> None:
    params = preset(vehicle)
    n, rng = 16, np.random.default_rng(5)
    pos = np.stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(-6, -0.5, n)])
    vel, rates, wind = rng.normal(0, 2, (3, n)), rng.normal(0, 1, (3, n)), rng.normal(0, 2, (3, n))
    q = np.array([euler_to_quat(*rng.normal(0, 0.5, 3)) for _ in range(n)]).T
    pos[2, ::5], vel[2, ::5] = -0.4, 5.0  # thrown at the ground: a crash
    pos[2, 1::5], vel[2, 1::5] = -0.2, 0.5  # a gentle touchdown
    seeds = rng.integers(0, 2**31, n)
    scalar = [Simulator(params, np.random.default_rng(int(s)), Spawn.thrown(pos[:, i], vel[:, i], rates[:, i], q[:, i]),
                        wind=Wind(tuple(wind[:, i]))) for i, s in enumerate(seeds)]  # fmt: skip
    batch = BatchSimulator(params, [np.random.default_rng(int(s)) for s in seeds], pos, vel, q, rates, wind_ned_m_s=wind)
    kinds = np.array([KINDS[i % 4] for i in range(n)])
    worst = 0.0
    for k in range(120):
        kind = np.full(n, MOTORS_OFF) if k < 15 else kinds  # thrown: motors off, then engaged
        sp = BatchSetpoint(
            kind, rng.normal(0, 4, (3, n)), np.where(np.arange(n) % 8 < 4, math.nan, rng.uniform(-3, 3, n)), rng.normal(0, 0.5, n),
            np.array([euler_to_quat(*rng.normal(0, 0.4, 3)) for _ in range(n)]).T, rng.uniform(0.2, 0.9, n), rng.normal(0, 1, (3, n)),
            np.arange(n) % 2 == 1, pos + rng.normal(0, 2, (3, n)), np.zeros((3, n)),
        )  # fmt: skip
        batch.advance(0.01, sp)
        err_p, err_v = batch.estimate_error()
        for i, s in enumerate(scalar):
            s.advance(0.01, _scalar_setpoint(sp, i))
            st = s.state()
            a = np.concatenate([st.position_ned_m, st.velocity_ned_m_s, st.q_ned_frd, st.rates_frd_rad_s, st.motor_thrust_n,
                                *s.estimate_error()])  # fmt: skip
            b = np.array([batch.px[i], batch.py[i], batch.pz[i], batch.vx[i], batch.vy[i], batch.vz[i], batch.qw[i], batch.qx[i],
                          batch.qy[i], batch.qz[i], batch.wx[i], batch.wy[i], batch.wz[i], *(t[i] for t in batch.t), *err_p[:, i],
                          *err_v[:, i]])  # fmt: skip
            worst = max(worst, float(np.max(np.abs(a - b))))
            assert (st.crashed, st.landed, st.motors_on) == (batch.crashed[i], batch.landed[i], batch.motors_on[i]), (k, i)
    assert worst <= 1e-9, worst
    assert batch.crashed.any()  # the ground contact was exercised
