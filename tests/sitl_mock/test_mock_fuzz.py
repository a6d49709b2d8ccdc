"""Malformed MAVLink into the autopilot: random setpoints, commands and parameter writes with
NaN / inf / huge values in every field never raise and never put a non-finite number into the
dynamics (the setpoint the simulator runs, the true state, the parameters)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.autopilot import Autopilot
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.testing import accel_setpoint, command_long

DT = 0.004
SPECIALS = (math.nan, math.inf, -math.inf, 1e30, -1e30, 0.0, 1.0)
PARAMS = (b"MPC_THR_HOVER", b"MOT_THST_HOVER", b"COM_OF_LOSS_T", b"GUID_OPTIONS", b"GUID_TIMEOUT")
COMMANDS = (176, 400, 22, 21, 511, 512, 11, 92, 178)  # set mode, arm, takeoff, land, intervals, ...


def _value(rng: np.random.Generator) -> float:
    return float(rng.choice(SPECIALS)) if rng.random() < 0.4 else float(rng.normal(0.0, 5.0))


def _message(rng: np.random.Generator):
    kind = int(rng.integers(5))
    if kind == 0:
        frame = int(rng.choice([1, 7, 8, 9, 5, 6]))
        return mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, frame, int(rng.integers(0, 1 << 16)), *[_value(rng) for _ in range(11)])
    if kind == 1:
        return mavlink.MAVLink_set_attitude_target_message(
            0, 1, 1, int(rng.integers(0, 256)), [_value(rng) for _ in range(4)], *[_value(rng) for _ in range(4)])
    if kind == 2:
        return command_long(int(rng.choice(COMMANDS)), *[_value(rng) for _ in range(7)])
    if kind == 3:
        return mavlink.MAVLink_param_set_message(1, 1, rng.choice(PARAMS), _value(rng), int(rng.choice([6, 9])))
    return accel_setpoint(_value(rng), _value(rng), _value(rng))


def _finite_setpoint(sp) -> bool:
    values = [v for v in vars(sp).values() if v is not None and not isinstance(v, (str, bool))]
    return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in values)


@pytest.mark.parametrize("profile", ["px4", "ardupilot"])
def test_malformed_traffic_never_reaches_the_dynamics(profile: str) -> None:
    rng = np.random.default_rng(1)
    kinds: set[str] = set()
    for _ in range(10):
        ap = Autopilot(replace(MockConfig(vehicle="fast", profile=profile, ekf_ready_delay_s=0.2),
                               spawn=SpawnSpec("hover", (0.0, 0.0, -10.0))))
        ap.add_link(0)
        for _ in range(125):
            ap.handle(accel_setpoint(0.0, 0.0, 0.0), 0)
            ap.step(DT)
        ap.handle(command_long(176, 1, 6 if profile == "px4" else 4), 0)
        assert ap.mode.name == ("OFFBOARD" if profile == "px4" else "GUIDED")
        for _ in range(400):
            ap.handle(_message(rng), 0)
            ap.step(DT)
            kinds.add(type(ap._dyn_setpoint).__name__)
            assert _finite_setpoint(ap._dyn_setpoint), ap._dyn_setpoint
            t = ap.truth
            assert np.all(np.isfinite(t.position_ned_m)) and np.all(np.isfinite(t.velocity_ned_m_s))
            assert np.all(np.isfinite(t.q_ned_frd)) and np.all(np.isfinite(t.rates_frd_rad_s))
        for name in PARAMS:
            value = ap.params.get(name.decode())
            assert value is None or math.isfinite(value), (name, value)
    # The fuzz reached the setpoint paths, not only the rejections.
    assert len(kinds) >= 3, kinds
