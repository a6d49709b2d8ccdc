"""The mock's ArduPilot GUIDED handling for N flights: per flight the scalar objects themselves
(the app's :class:`~pf_offboard.app.encoders.Encoder`, the message as it crosses the wire, the
mock's ``ardupilot_*_target`` parsing and :class:`sitl_mock.control.ArduGuided`), their dynamics
setpoints gathered into one :class:`~pf_offboard.sim.batch.dynamics.BatchSetpoint` for the batched
dynamics. Exact by construction (the same functions on the same inputs); the per-flight Python
costs ~0.1 ms a flight-step, small beside the 1 kHz physics it leaves batched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pf_offboard.sim.batch.dynamics import ACCEL, ATTITUDE, MOTORS_OFF, POSITION, RATES, BatchSetpoint

Arr = NDArray[np.float64]


@dataclass(frozen=True)
class _Cmd:
    """One flight's row of the batch command (the encoder's CommandLike)."""

    acceleration: Any
    thrust: float
    attitude: Any
    body_rates: Any
    yaw: float
    yaw_rate: float


class ArduPilotOffboard:
    """GUIDED for N flights: the state a thrown start spawns in (the mock's GUIDED without an
    entry: its initial hold), then the app's setpoints as ArduCopter takes them."""

    def __init__(self, setup: Any, n: int) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink
        from sitl_mock.control import ArduGuided
        from sitl_mock.profiles import PROFILES as MOCK_PROFILES

        from pf_offboard.app.encoders import Encoder

        self.n = n
        self.output_mode = setup.flight.output_mode
        params = {p.name: p.default for p in MOCK_PROFILES["ardupilot"].params}
        # SimFlight sets GUID_OPTIONS to what the output mode needs (like `fly --set-guid-options`)
        required = setup.profile.required_guid_options(self.output_mode)
        if required:
            params["GUID_OPTIONS"] = float(required)
        self.params = params
        self.autopilot_hover_thrust = float(setup.vehicle.hover_thrust)
        self.encoder = Encoder(self.output_mode, setup.profile, 1, 1, hover_thrust=setup.hover_thrust,
                               time_constant_s=setup.flight.attitude_time_constant_s,
                               tilt_from_gravity=setup.tilt_from_gravity)  # fmt: skip
        # the pipeline's rates output: ArduCopter's is the law alone (rates_through_attitude_target),
        # stateless, so one encoder serves every flight
        from pf_offboard.app.pipeline import rates_output_for

        self.encoder.rates_output = rates_output_for(setup.follower, setup.profile, self.encoder.rate_law)
        if self.encoder.rates_output.reference_lag_s is not None:
            raise ValueError("the batch engine's ArduPilot handling shares one encoder: a stateful rates output needs one per flight")
        self.guided = [ArduGuided() for _ in range(n)]
        self._mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self._mav.robust_parsing = True

    def _wire(self, msg: Any) -> Any:
        """The message as the mock decodes it (float32 fields)."""
        return self._mav.decode(bytearray(msg.pack(self._mav)))

    def setpoint(self, cmd: Any, est: list[Any], time_ms: int, now_s: float, dt_s: float, pos: Arr, vel: Arr,
                 q: Arr, landed: Any, alive: Any, send: bool, est_offset: Arr) -> BatchSetpoint:  # fmt: skip
        from sitl_mock.dynamics import AccelerationSetpoint, AttitudeSetpoint, MotorsOff, RateSetpoint
        from sitl_mock.setpoints import BrakeAndHover, Rejected, ardupilot_attitude_target, ardupilot_position_target

        n = self.n
        kind = np.zeros(n, dtype=np.int64)
        acc = np.zeros((3, n))
        yaw = np.full(n, math.nan)
        yaw_rate = np.zeros(n)
        qs = np.tile([[1.0], [0.0], [0.0], [0.0]], n)
        thrust = np.zeros(n)
        rates = np.zeros((3, n))
        has_ff = np.zeros(n, dtype=bool)
        hold = np.zeros((3, n))
        p = self.params
        for k in range(n):
            g = self.guided[k]
            pk, vk = pos[:, k].copy(), vel[:, k].copy()
            if send and alive[k]:
                c = _Cmd(cmd.acceleration[k], float(cmd.thrust[k]), cmd.attitude[k], cmd.body_rates[k], float(cmd.yaw[k]),
                         float(cmd.yaw_rate[k]))  # fmt: skip
                msg = self._wire(self.encoder.encode(c, est[k], time_ms).message)
                if msg.get_type() == "SET_ATTITUDE_TARGET":
                    r = ardupilot_attitude_target(msg, thrust_is_thrust=bool(int(p["GUID_OPTIONS"]) & 8),
                                                  speed_up_m_s=p["WPNAV_SPEED_UP"] / 100.0, speed_down_m_s=p["WPNAV_SPEED_DN"] / 100.0)  # fmt: skip
                    if isinstance(r, BrakeAndHover):
                        g.hold(pk, vk, float(_yaw_of(q[:, k])))
                    elif not isinstance(r, Rejected):
                        g.set_angle(r, now_s)
                else:
                    r = ardupilot_position_target(msg, pk, float(_yaw_of(q[:, k])))
                    if not isinstance(r, Rejected):
                        g.set_trajectory(r, now_s, pk, vk)
            sp = g.update(dt_s, now_s, p["GUID_TIMEOUT"], int(p["GUID_OPTIONS"]), p["PSC_JERK_XY"], p["PSC_JERK_Z"],
                          self.autopilot_hover_thrust, pk, vk, q[:, k], bool(landed[k]))  # fmt: skip
            if sp is None:
                if bool(landed[k]) and g.submode != "takeoff":
                    sp = MotorsOff()
                else:
                    kind[k] = POSITION
                    hold[:, k] = g.hold_position - est_offset[:, k]
                    yaw[k] = math.nan if g.yaw_t is None else g.yaw_t
                    continue
            if isinstance(sp, AccelerationSetpoint):
                kind[k] = ACCEL
                acc[:, k] = sp.accel_ned_m_s2
                yaw[k] = math.nan if sp.yaw_rad is None else sp.yaw_rad
                yaw_rate[k] = sp.yaw_rate_rad_s
            elif isinstance(sp, AttitudeSetpoint):
                kind[k] = ATTITUDE
                qs[:, k] = sp.q_ned_frd
                thrust[k] = sp.thrust_norm
                if sp.rates_ff_frd_rad_s is not None:
                    rates[:, k] = sp.rates_ff_frd_rad_s
                    has_ff[k] = True
            elif isinstance(sp, RateSetpoint):
                kind[k] = RATES
                rates[:, k] = sp.rates_frd_rad_s
                thrust[k] = sp.thrust_norm
            else:
                kind[k] = MOTORS_OFF
        return BatchSetpoint(kind, acc, yaw, yaw_rate, qs, thrust, rates, has_ff, hold, np.zeros((3, n)))


def _yaw_of(q: Arr) -> float:
    from sitl_mock.rotations import euler_from_q

    return float(euler_from_q(q)[2])
