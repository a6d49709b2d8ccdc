"""Pure quadrotor simulation for the mock autopilot (no networking). World NED, body FRD.

    from sitl_mock.dynamics import Simulator, preset, Spawn, AccelerationSetpoint
    sim = Simulator(preset("fast"), rng=np.random.default_rng(0), spawn=Spawn.hover((0, 0, -2)))
    state = sim.step(0.004, AccelerationSetpoint((0.0, 0.0, 0.0)))

See docs/sitl-mock-dynamics.md.
"""

from .estimator import EstimatorNoise
from .params import (
    DEFAULT_VEHICLE,
    GRAVITY_M_S2,
    PRESET_NAMES,
    REALISTIC_VEHICLE,
    CascadeGains,
    VehicleParams,
    cascade_gains_for_poles,
    preset,
)
from .sim import PHYSICS_DT_S, PHYSICS_RATE_HZ, Simulator, quat_mul
from .types import (
    AccelerationSetpoint,
    AttitudeSetpoint,
    Gust,
    MotorsOff,
    PositionSetpoint,
    Push,
    RateSetpoint,
    SensorNoise,
    Setpoint,
    Spawn,
    VehicleState,
    Wind,
    euler_to_quat,
    quat_to_euler,
)

__all__ = [
    "DEFAULT_VEHICLE", "GRAVITY_M_S2", "PHYSICS_DT_S", "PHYSICS_RATE_HZ", "PRESET_NAMES", "REALISTIC_VEHICLE",
    "AccelerationSetpoint", "AttitudeSetpoint", "CascadeGains", "EstimatorNoise", "Gust", "MotorsOff", "PositionSetpoint", "Push",
    "RateSetpoint", "SensorNoise", "Setpoint", "Simulator", "Spawn", "VehicleParams", "VehicleState", "Wind",
    "cascade_gains_for_poles", "euler_to_quat", "preset", "quat_mul", "quat_to_euler",
]
