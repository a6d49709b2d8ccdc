"""In-process simulation speed of :mod:`sitl_mock.dynamics` (× real time at 1 kHz physics).

Called by ``pf-offboard bench --only sim``; prints nothing itself, returns a flat dict. Timing
is measured here and never asserted in tests.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .params import preset
from .sim import PHYSICS_RATE_HZ, Simulator
from .types import AccelerationSetpoint, AttitudeSetpoint, RateSetpoint, Setpoint, Spawn


def _hover(_: float) -> Setpoint:
    return AccelerationSetpoint((0.0, 0.0, 0.0), yaw_rad=0.0)


_HOVER_SP = _hover(0.0)


def _aggressive(t: float) -> Setpoint:
    """A 2 m-radius circle at 4 rad/s (32 m/s² centripetal, clipped by the tilt limit) + yaw spin."""
    w = 4.0
    return AccelerationSetpoint((-8.0 * w * w / 4.0 * math.cos(w * t), -8.0 * math.sin(w * t), 0.0),
                                yaw_rad=None, yaw_rate_rad_s=1.0)


def _measure(preset_name: str, setpoint_at: Callable[[float], Setpoint], step_s: float, sim_s: float,
             build_state: bool, repeats: int) -> float:
    """Best-of-``repeats`` wall time per 1 kHz physics tick, microseconds."""
    best = math.inf
    n_calls = int(round(sim_s / step_s))
    for r in range(repeats):
        sim = Simulator(preset(preset_name), np.random.default_rng(r), Spawn.hover((0.0, 0.0, -10.0)))
        # Setpoints are built outside the timed loop: we time the simulator, not the caller.
        setpoints = [setpoint_at(i * step_s) for i in range(n_calls)]
        run = sim.step if build_state else sim.advance
        t0 = time.perf_counter()
        for sp in setpoints:
            run(step_s, sp)
        elapsed = time.perf_counter() - t0
        best = min(best, elapsed / (sim.time_s * PHYSICS_RATE_HZ))
    return best * 1e6


def run_inprocess(quick: bool = False) -> dict[str, Any]:
    """Speed figures: µs per 1 kHz physics tick and × real time, for a hover and an aggressive
    manoeuvre, calling ``step`` at 250 Hz (typical offboard rate) and at 1 kHz."""
    sim_s = 2.0 if quick else 10.0
    repeats = 1 if quick else 5
    out: dict[str, Any] = {"physics_rate_hz": PHYSICS_RATE_HZ}
    cases = (
        ("fast_hover_step4ms", "fast", _hover, 0.004, True),
        ("fast_aggressive_step4ms", "fast", _aggressive, 0.004, True),
        ("fast_aggressive_advance4ms", "fast", _aggressive, 0.004, False),
        ("fast_aggressive_step20ms", "fast", _aggressive, 0.020, True),
        ("fast_aggressive_step1ms", "fast", _aggressive, 0.001, True),
        ("px4default_aggressive_step4ms", "px4-default", _aggressive, 0.004, True),
        # Estimator error (10 Hz fusion) and the 60 ms setpoint latency on.
        ("px4sih_aggressive_step4ms", "px4-sih", _aggressive, 0.004, True),
        ("fast_attitude_step4ms", "fast",
         lambda t: AttitudeSetpoint((math.cos(0.2), math.sin(0.2), 0.0, 0.0), 0.35, (0.0, 0.0, 0.5)), 0.004, True),
        ("fast_rates_step4ms", "fast", lambda t: RateSetpoint((0.0, 0.0, 0.3), 0.3), 0.004, True),
    )
    for key, name, sp, step_s, build in cases:
        us = _measure(name, sp, step_s, sim_s, build, repeats)
        out[f"{key}_us_per_tick"] = us
        out[f"{key}_x_realtime"] = 1e6 / (us * PHYSICS_RATE_HZ)
    return out


if __name__ == "__main__":  # pragma: no cover - manual use
    for k, v in run_inprocess().items():
        print(f"{k:<45} {v:.4g}" if isinstance(v, float) else f"{k:<45} {v}")
