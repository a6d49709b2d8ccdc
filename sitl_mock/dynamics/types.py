"""Value objects of the dynamics API: setpoints, spawn states, wind, vehicle state (NED / FRD).

Setpoints validate on construction: NaN/inf or out-of-range values raise ValueError naming the
field, so nothing invalid ever reaches the physics. Vectors are stored as tuples of floats
(immutable, cheap to read in the simulation loop).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Union

import numpy as np
from numpy.typing import NDArray

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def _vec(owner: str, name: str, value: object, n: int = 3) -> tuple[float, ...]:
    try:
        items = [float(v) for v in value]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name}: expected {n} numbers, got {value!r}") from None
    if len(items) != n:
        raise ValueError(f"{owner}.{name}: expected {n} numbers, got {len(items)}")
    for i, v in enumerate(items):
        if not math.isfinite(v):
            raise ValueError(f"{owner}.{name}[{i}]: must be finite, got {v!r}")
    return tuple(items)


def _num(owner: str, name: str, value: object, lo: float = -math.inf, hi: float = math.inf) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{owner}.{name}: must be finite, got {v!r}")
    if not lo <= v <= hi:
        raise ValueError(f"{owner}.{name}: must be in [{lo}, {hi}], got {v!r}")
    return v


def _unit_quat(owner: str, name: str, value: object) -> Quat:
    q = _vec(owner, name, value, 4)
    norm = math.sqrt(sum(c * c for c in q))
    # A real autopilot rejects clearly non-unit quaternions; tiny rounding is renormalised.
    if abs(norm - 1.0) > 1e-2:
        raise ValueError(f"{owner}.{name}: not a unit quaternion (norm {norm:.6g})")
    w, x, y, z = (c / norm for c in q)
    return (w, x, y, z)


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)


# ----------------------------------------------------------------------------------------------
# Setpoints
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AccelerationSetpoint:
    """PX4 OFFBOARD acceleration: world NED acceleration (gravity excluded) + yaw.

    ``yaw_rad`` None holds the current heading (advanced by ``yaw_rate_rad_s``); otherwise
    ``yaw_rate_rad_s`` is a yaw-rate feed-forward about world z.
    """

    accel_ned_m_s2: Vec3
    yaw_rad: float | None = None
    yaw_rate_rad_s: float = 0.0

    def __post_init__(self) -> None:
        _set(self, "accel_ned_m_s2", _vec("AccelerationSetpoint", "accel_ned_m_s2", self.accel_ned_m_s2))
        if self.yaw_rad is not None:
            _set(self, "yaw_rad", _num("AccelerationSetpoint", "yaw_rad", self.yaw_rad))
        _set(self, "yaw_rate_rad_s", _num("AccelerationSetpoint", "yaw_rate_rad_s", self.yaw_rate_rad_s))


@dataclass(frozen=True)
class AttitudeSetpoint:
    """Attitude (body FRD → world NED) + normalised collective thrust 0..1.

    ``rates_ff_frd_rad_s``, when given, is added to the attitude controller's rate setpoint as
    body-rate feed-forward (the MAVLink layer decides what to pass: PX4 keeps only yaw).
    """

    q_ned_frd: Quat
    thrust_norm: float
    rates_ff_frd_rad_s: Vec3 | None = None

    def __post_init__(self) -> None:
        _set(self, "q_ned_frd", _unit_quat("AttitudeSetpoint", "q_ned_frd", self.q_ned_frd))
        _set(self, "thrust_norm", _num("AttitudeSetpoint", "thrust_norm", self.thrust_norm, 0.0, 1.0))
        if self.rates_ff_frd_rad_s is not None:
            _set(self, "rates_ff_frd_rad_s",
                 _vec("AttitudeSetpoint", "rates_ff_frd_rad_s", self.rates_ff_frd_rad_s))


@dataclass(frozen=True)
class RateSetpoint:
    """Body rates FRD + normalised collective thrust 0..1 (straight to the rate controller)."""

    rates_frd_rad_s: Vec3
    thrust_norm: float

    def __post_init__(self) -> None:
        _set(self, "rates_frd_rad_s", _vec("RateSetpoint", "rates_frd_rad_s", self.rates_frd_rad_s))
        _set(self, "thrust_norm", _num("RateSetpoint", "thrust_norm", self.thrust_norm, 0.0, 1.0))


@dataclass(frozen=True)
class PositionSetpoint:
    """The autopilot's own position controller (hold, loiter, takeoff, land, brake).

    A target below the ground (z > 0 in NED) lands: the descent is limited to the land speed.
    ``yaw_rad`` None holds the current heading.
    """

    position_ned_m: Vec3
    velocity_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    yaw_rad: float | None = None

    def __post_init__(self) -> None:
        _set(self, "position_ned_m", _vec("PositionSetpoint", "position_ned_m", self.position_ned_m))
        _set(self, "velocity_ned_m_s", _vec("PositionSetpoint", "velocity_ned_m_s", self.velocity_ned_m_s))
        if self.yaw_rad is not None:
            _set(self, "yaw_rad", _num("PositionSetpoint", "yaw_rad", self.yaw_rad))


@dataclass(frozen=True)
class MotorsOff:
    """Disarmed, or armed with motors locked (throw launch): zero thrust, ballistic flight."""


Setpoint = Union[AccelerationSetpoint, AttitudeSetpoint, RateSetpoint, PositionSetpoint, MotorsOff]


# ----------------------------------------------------------------------------------------------
# Spawn
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Spawn:
    """Initial state. Use :meth:`ground`, :meth:`hover` or :meth:`thrown`."""

    position_ned_m: Vec3
    velocity_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    q_ned_frd: Quat = (1.0, 0.0, 0.0, 0.0)
    rates_frd_rad_s: Vec3 = (0.0, 0.0, 0.0)
    motors_at_hover: bool = False  # motors already spinning at the true hover thrust

    def __post_init__(self) -> None:
        _set(self, "position_ned_m", _vec("Spawn", "position_ned_m", self.position_ned_m))
        if self.position_ned_m[2] > 0.0:
            raise ValueError(f"Spawn.position_ned_m[2]: below the ground (NED z > 0), got {self.position_ned_m[2]!r}")
        _set(self, "velocity_ned_m_s", _vec("Spawn", "velocity_ned_m_s", self.velocity_ned_m_s))
        _set(self, "q_ned_frd", _unit_quat("Spawn", "q_ned_frd", self.q_ned_frd))
        _set(self, "rates_frd_rad_s", _vec("Spawn", "rates_frd_rad_s", self.rates_frd_rad_s))

    @staticmethod
    def ground(position_ned_m: Sequence[float] = (0.0, 0.0, 0.0), yaw_rad: float = 0.0) -> Spawn:
        """Resting on the ground (z forced to 0), motors off, level."""
        p = _vec("Spawn", "position_ned_m", position_ned_m)
        yaw = _num("Spawn", "yaw_rad", yaw_rad)
        return Spawn((p[0], p[1], 0.0), q_ned_frd=_yaw_quat(yaw))

    @staticmethod
    def hover(position_ned_m: Sequence[float], yaw_rad: float = 0.0) -> Spawn:
        """Level, at rest, motors at the true hover thrust."""
        yaw = _num("Spawn", "yaw_rad", yaw_rad)
        return Spawn(tuple(position_ned_m), q_ned_frd=_yaw_quat(yaw), motors_at_hover=True)  # type: ignore[arg-type]

    @staticmethod
    def thrown(
        position_ned_m: Sequence[float],
        velocity_ned_m_s: Sequence[float],
        rates_frd_rad_s: Sequence[float] = (0.0, 0.0, 0.0),
        q_ned_frd: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
    ) -> Spawn:
        """In the air with a velocity and spin, motors stopped: ballistic while MotorsOff is commanded."""
        return Spawn(tuple(position_ned_m), tuple(velocity_ned_m_s), tuple(q_ned_frd),  # type: ignore[arg-type]
                     tuple(rates_frd_rad_s))  # type: ignore[arg-type]


def _yaw_quat(yaw_rad: float) -> Quat:
    return (math.cos(0.5 * yaw_rad), 0.0, 0.0, math.sin(0.5 * yaw_rad))


# ----------------------------------------------------------------------------------------------
# Wind
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Gust:
    """A (1 − cos) gust: wind rises from 0 to ``velocity_ned_m_s`` and back over ``duration_s``."""

    start_s: float
    duration_s: float
    velocity_ned_m_s: Vec3

    def __post_init__(self) -> None:
        _set(self, "start_s", _num("Gust", "start_s", self.start_s, 0.0))
        _set(self, "duration_s", _num("Gust", "duration_s", self.duration_s, 1e-6))
        _set(self, "velocity_ned_m_s", _vec("Gust", "velocity_ned_m_s", self.velocity_ned_m_s))

    def at(self, time_s: float) -> Vec3:
        u = (time_s - self.start_s) / self.duration_s
        if not 0.0 < u < 1.0:
            return (0.0, 0.0, 0.0)
        k = 0.5 * (1.0 - math.cos(2.0 * math.pi * u))
        gx, gy, gz = self.velocity_ned_m_s
        return (k * gx, k * gy, k * gz)


@dataclass(frozen=True)
class Push:
    """An external push: a constant specific force ``accel_ned_m_s2`` (force / mass, m/s², world
    NED) on the airframe from ``start_s`` for ``duration_s`` seconds of simulated time (a shove, a
    collision, a downwash). It acts on the translation only, on top of thrust, gravity and drag."""

    start_s: float
    duration_s: float
    accel_ned_m_s2: Vec3

    def __post_init__(self) -> None:
        _set(self, "start_s", _num("Push", "start_s", self.start_s, 0.0))
        _set(self, "duration_s", _num("Push", "duration_s", self.duration_s, 1e-3, 3600.0))
        _set(self, "accel_ned_m_s2", _vec("Push", "accel_ned_m_s2", self.accel_ned_m_s2))
        if math.sqrt(sum(a * a for a in self.accel_ned_m_s2)) > MAX_PUSH_M_S2:
            raise ValueError(f"Push.accel_ned_m_s2: must be <= {MAX_PUSH_M_S2:g} m/s^2, got {self.accel_ned_m_s2}")


MAX_PUSH_M_S2 = 100.0  # about 10 g: beyond it the airframe would not survive the push


@dataclass(frozen=True)
class Wind:
    """Mean wind + scheduled gusts + optional turbulence (first-order Gauss–Markov per axis,
    drawn from the simulator's Generator). Air velocity in world NED."""

    mean_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gusts: tuple[Gust, ...] = ()
    turbulence_std_m_s: float = 0.0
    turbulence_time_constant_s: float = 1.0

    def __post_init__(self) -> None:
        _set(self, "mean_ned_m_s", _vec("Wind", "mean_ned_m_s", self.mean_ned_m_s))
        gusts = tuple(self.gusts)
        for i, g in enumerate(gusts):
            if not isinstance(g, Gust):
                raise ValueError(f"Wind.gusts[{i}]: expected a Gust, got {g!r}")
        _set(self, "gusts", gusts)
        _set(self, "turbulence_std_m_s", _num("Wind", "turbulence_std_m_s", self.turbulence_std_m_s, 0.0))
        _set(self, "turbulence_time_constant_s",
             _num("Wind", "turbulence_time_constant_s", self.turbulence_time_constant_s, 1e-3))


# ----------------------------------------------------------------------------------------------
# Sensors
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensorNoise:
    """Telemetry imperfections for :meth:`Simulator.measure`: white noise (1-σ) and a delay."""

    position_std_m: float = 0.0
    velocity_std_m_s: float = 0.0
    attitude_std_rad: float = 0.0
    rates_std_rad_s: float = 0.0
    accel_std_m_s2: float = 0.0
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("position_std_m", "velocity_std_m_s", "attitude_std_rad", "rates_std_rad_s",
                     "accel_std_m_s2", "delay_s"):
            _set(self, name, _num("SensorNoise", name, getattr(self, name), 0.0))


# ----------------------------------------------------------------------------------------------
# State
# ----------------------------------------------------------------------------------------------


def _ro(values: Sequence[float]) -> NDArray[np.float64]:
    a = np.array(values, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class VehicleState:
    """Snapshot of the simulated vehicle (true state unless it came from ``measure()``).

    Arrays are read-only float64. ``accel_ned_m_s2`` is the KINEMATIC acceleration (gravity
    included, i.e. d²p/dt²); ``specific_force_frd_m_s2`` is what an accelerometer reads.
    """

    time_s: float
    position_ned_m: NDArray[np.float64]
    velocity_ned_m_s: NDArray[np.float64]
    accel_ned_m_s2: NDArray[np.float64]
    q_ned_frd: NDArray[np.float64]
    rates_frd_rad_s: NDArray[np.float64]
    motor_thrust_n: NDArray[np.float64]
    landed: bool
    crashed: bool
    specific_force_frd_m_s2: NDArray[np.float64] = field(default_factory=lambda: _ro((0.0, 0.0, 0.0)))
    thrust_norm_actual: float = 0.0  # total motor thrust / total maximum thrust
    thrust_norm_sp: float = 0.0  # collective thrust the autopilot commands, 0..1
    q_sp_ned_frd: NDArray[np.float64] = field(default_factory=lambda: _ro((1.0, 0.0, 0.0, 0.0)))
    rates_sp_frd_rad_s: NDArray[np.float64] = field(default_factory=lambda: _ro((0.0, 0.0, 0.0)))
    motors_on: bool = False  # False under MotorsOff
    wind_ned_m_s: NDArray[np.float64] = field(default_factory=lambda: _ro((0.0, 0.0, 0.0)))

    @property
    def euler_rad(self) -> Vec3:
        """(roll, pitch, yaw) ZYX Euler angles of ``q_ned_frd``."""
        return quat_to_euler(tuple(self.q_ned_frd))  # type: ignore[arg-type]


def quat_to_euler(q: Quat) -> Vec3:
    """ZYX (yaw-pitch-roll) Euler angles (roll, pitch, yaw) of a body→world quaternion."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (roll, pitch, yaw)


def euler_to_quat(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quat:
    """Body→world quaternion (w, x, y, z) of ZYX Euler angles."""
    cr, sr = math.cos(0.5 * roll_rad), math.sin(0.5 * roll_rad)
    cp, sp = math.cos(0.5 * pitch_rad), math.sin(0.5 * pitch_rad)
    cy, sy = math.cos(0.5 * yaw_rad), math.sin(0.5 * yaw_rad)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )
