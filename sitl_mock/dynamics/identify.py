"""Measure the closed inner loops: 63 % rise time of an acceleration-setpoint step.

Used by the tests and to produce the figures in docs/sitl-mock-dynamics.md.
"""

from __future__ import annotations

import numpy as np

from .params import VehicleParams
from .sim import Simulator
from .types import AccelerationSetpoint, AttitudeSetpoint, Spawn


def accel_step_rise_time_s(params: VehicleParams, step_ned_m_s2: tuple[float, float, float],
                           duration_s: float = 1.0) -> float:
    """Time for the kinematic acceleration to reach 63 % of an acceleration-setpoint step,
    starting from a hover, with drag switched off and the autopilot's hover thrust set to the
    true one (so the response starts at zero and ends at the setpoint).

    The component measured is the step's direction (the step must be along one axis). A wrong
    hover-thrust parameter (``px4-sih``'s 0.5 for 0.49, as PX4 flies SIH) scales and offsets the
    response — what identify fits as gain and bias — without changing its timing; left in, it
    started the vertical step from +0.2 m/s^2, and the 63 % mark came at 0.095 s going up and
    0.144 s going down for the same 0.114 s response (the preset then, with one setpoint latency
    for thrust and tilt; its thrust latency has made it 0.062 s since).
    """
    axis = int(np.argmax(np.abs(step_ned_m_s2)))
    target = float(step_ned_m_s2[axis])
    if target == 0.0 or sum(1 for c in step_ned_m_s2 if c != 0.0) != 1:
        raise ValueError("accel_step_rise_time_s.step_ned_m_s2: need a non-zero step along one axis")
    matched = params.with_(drag_1_s=0.0, hover_thrust=params.true_hover_thrust)
    sim = Simulator(matched, np.random.default_rng(0), Spawn.hover((0.0, 0.0, -50.0)))
    sp = AccelerationSetpoint(step_ned_m_s2, yaw_rad=0.0)
    t_prev, a_prev = 0.0, 0.0
    for _ in range(int(round(duration_s * 1000))):
        s = sim.step(0.001, sp)
        a = s.accel_ned_m_s2[axis] / target
        if a >= 0.632:  # interpolate within the 1 ms step
            return t_prev + (s.time_s - t_prev) * (0.632 - a_prev) / (a - a_prev)
        t_prev, a_prev = s.time_s, a
    return float("inf")


def attitude_gain(params: VehicleParams, frequency_hz: float, amplitude_rad: float = 0.002) -> float:
    """Closed-loop roll amplitude ratio |roll / roll_sp| for a sinusoidal roll setpoint
    (small amplitude: the linear regime; large ones saturate the motors)."""
    sim = Simulator(params, np.random.default_rng(0), Spawn.hover((0.0, 0.0, -50.0)))
    duration = max(1.0, 8.0 / frequency_hz)
    w = 2.0 * np.pi * frequency_hz
    times, rolls = [], []
    for i in range(int(round(duration * 1000))):
        t = i * 0.001
        roll_sp = amplitude_rad * np.sin(w * t)
        q = (np.cos(0.5 * roll_sp), np.sin(0.5 * roll_sp), 0.0, 0.0)
        s = sim.step(0.001, AttitudeSetpoint(q, params.hover_thrust))
        times.append(s.time_s)
        rolls.append(s.euler_rad[0])
    ts, rs = np.array(times), np.array(rolls)
    # Fourier coefficient over the second half (whole periods are not needed for a ratio this coarse).
    keep = ts >= duration / 2
    n_periods = np.floor((ts[keep][-1] - ts[keep][0]) * frequency_hz)
    keep &= ts < ts[keep][0] + n_periods / frequency_hz
    coeff = 2.0 * np.mean(rs[keep] * np.exp(-1j * w * ts[keep]))
    return float(abs(coeff) / amplitude_rad)


def attitude_bandwidth_hz(params: VehicleParams, amplitude_rad: float = 0.002) -> float:
    """Lowest frequency where the roll amplitude ratio falls below 1/√2 (bisection, 0.25 Hz)."""
    lo, hi = 0.5, 100.0
    if attitude_gain(params, lo, amplitude_rad) < 0.7071:
        return lo
    while hi - lo > 0.25:
        mid = 0.5 * (lo + hi)
        if attitude_gain(params, mid, amplitude_rad) >= 0.7071:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
