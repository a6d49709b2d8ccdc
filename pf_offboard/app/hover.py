"""The hover thrust the autopilot itself flies, measured from its attitude target while it holds.

attitude / rates output send a normalised thrust scaled by a hover thrust (encoders.thrust_normalised).
PX4's parameter MPC_THR_HOVER is only where its hover-thrust estimator starts: the estimate it then
flies is never written back, so a vehicle heavier or lighter than the parameter says is sent the
wrong thrust for every acceleration until the in-flight identification finds the gain (real PX4
SIH at 1.5 kg, hover 0.61 against MPC_THR_HOVER 0.5: a racetrack at 3 m/s 10.8 / 12.2 cm RMS in
`attitude` / `rates` output, 4.0 / 6.2 with the measured value; docs/design-decisions.md). While
the autopilot holds the vehicle still it streams ATTITUDE_TARGET with the thrust it hovers on.
Pure: fed samples, no I/O.
"""

from __future__ import annotations

import math
import statistics
from collections import deque

# Samples over this window before activation (the autopilot's clock, s; PX4 streams ATTITUDE_TARGET
# at 2-10 Hz depending on the link's MAVLink mode)
WINDOW_S = 1.5
MIN_SAMPLES = 3
# The vehicle counts as holding still below this speed (m/s), and the samples as one hover when
# they spread at most this much (normalised thrust)
STILL_SPEED_M_S = 0.3
MAX_SPREAD = 0.05
# A normalised hover thrust some vehicle hovers at: the range the config's flight.hover_thrust, the
# autopilot's parameter (dialects.base.read_setpoint_mapping) and a measured value must lie in
HOVER_THRUST_RANGE = (0.05, 0.95)


def plausible_hover_thrust(value: float) -> bool:
    """Whether ``value`` (normalised) is a hover thrust some vehicle hovers at (HOVER_THRUST_RANGE)."""
    return HOVER_THRUST_RANGE[0] <= value <= HOVER_THRUST_RANGE[1]


class HoverThrustMeter:
    """The autopilot's hover thrust from its attitude targets while the vehicle holds still."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = float(window_s)
        self._samples: deque[tuple[float, float]] = deque()  # (autopilot s, thrust) while still

    def add(self, time_s: float, thrust: float, speed_m_s: float | None) -> None:
        """One ATTITUDE_TARGET's thrust stamped ``time_s`` (its time_boot_ms); ``speed_m_s``: the
        vehicle's then (None: no state yet). A sample while moving, not finite or older than the
        last (a clock jump) starts the window again."""
        still = (speed_m_s is not None and math.isfinite(speed_m_s) and speed_m_s <= STILL_SPEED_M_S
                 and math.isfinite(thrust) and math.isfinite(time_s))  # fmt: skip
        if not still or (self._samples and time_s < self._samples[-1][0]):
            self._samples.clear()
        if not still:
            return
        self._samples.append((float(time_s), float(thrust)))
        while self._samples[0][0] < time_s - self.window_s:
            self._samples.popleft()

    def hover_thrust(self) -> float | None:
        """The median thrust over the window up to the newest sample: None with fewer than
        MIN_SAMPLES, a spread above MAX_SPREAD or a value no vehicle hovers at."""
        values = sorted(t for _, t in self._samples)
        if len(values) < MIN_SAMPLES or values[-1] - values[0] > MAX_SPREAD:
            return None
        median = statistics.median(values)
        return median if plausible_hover_thrust(median) else None
