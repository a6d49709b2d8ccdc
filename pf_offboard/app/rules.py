"""Pure decision rules of a flight: when a throw fires, laps, when a take-off is settled, when
following ends. No I/O, no clocks: each is fed samples and tested on its own."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pf_offboard.errors import InputError


class ThrowTrigger:
    """Fires once, the moment a thrown vehicle crosses the activation height.

    Crossing in either direction counts (thrown up through H from the hand, or falling through H
    after being thrown above it), but only while the vehicle is in free flight: speed at least
    ``min_speed_m_s`` (a vehicle carried slowly past H does not fire) and ``confirm`` consecutive
    samples on the far side of H (a single noisy sample does not fire). The first altitude seen
    sets which side we start on; nothing fires until the vehicle has been seen on one side.
    """

    def __init__(self, height_m: float, min_speed_m_s: float = 0.5, confirm: int = 2) -> None:
        if not (math.isfinite(height_m) and height_m > 0.0):
            raise InputError("--throw", f"activation height must be > 0 m, got {height_m}")
        self.height_m = height_m
        self.min_speed_m_s = min_speed_m_s
        self.confirm = confirm
        self._side: bool | None = None  # True: above H
        self._beyond = 0
        self.fired = False

    def update(self, altitude_m: float, speed_m_s: float) -> bool:
        """Feed one state sample; True exactly once, on the confirming sample of a crossing."""
        if self.fired:
            return False
        above = altitude_m >= self.height_m
        if self._side is None:
            self._side = above
            return False
        if above == self._side:
            self._beyond = 0
            return False
        if speed_m_s < self.min_speed_m_s:
            # a slow crossing (carried by hand, drifting): accept the new side without firing
            self._side, self._beyond = above, 0
            return False
        self._beyond += 1
        if self._beyond >= self.confirm:
            self.fired = True
            return True
        return False


class LapCounter:
    """Laps completed: *net* progress along the path (η1 samples, metres) over its length.

    Each difference of η1 is taken modulo the length on closed paths (the shorter way round, so
    the wrap at the start point is unwrapped) and summed with its sign, so jitter back and forth
    cancels instead of accumulating. ``direction`` is the sign of travel (the sign of η2_ref):
    progress against it counts negative. ``None``: either direction, the magnitude of the net
    progress. Laps are never negative.
    """

    def __init__(self, length_m: float, closed: bool, direction: float | None = None) -> None:
        self.length_m = length_m
        self.closed = closed
        self.direction = None if direction is None else (1.0 if direction >= 0.0 else -1.0)
        self._last: float | None = None
        self.progress_m = 0.0  # signed net progress since the first sample (η1 units)

    def update(self, eta1_m: float) -> float:
        if not math.isfinite(eta1_m):
            return self.laps
        if self._last is not None:
            d = eta1_m - self._last
            if self.closed and self.length_m > 0:
                d = (d + 0.5 * self.length_m) % self.length_m - 0.5 * self.length_m
            self.progress_m += d
        self._last = eta1_m
        return self.laps

    @property
    def travelled_m(self) -> float:
        """Net path length travelled in the direction of travel (m, >= 0)."""
        net = abs(self.progress_m) if self.direction is None else self.direction * self.progress_m
        return max(0.0, net)

    @property
    def laps(self) -> float:
        return self.travelled_m / self.length_m if self.length_m > 0 else 0.0


class TakeoffSettle:
    """When a take-off counts as done: the vehicle holds the take-off altitude, on average.

    A vehicle hovering on GPS never sits still (PX4 SIH holds at 0.13-0.43 m/s), so a
    per-sample rule "within 0.1 m and below 0.1 m/s" may never hold. Instead: over the last
    ``window_s`` of vehicle time (at least that much history), the mean altitude error is within
    ``altitude_tol_m`` and the mean speed below ``speed_tol_m_s``. Pure; feed state samples.
    """

    def __init__(self, height_m: float, altitude_tol_m: float = 0.3, speed_tol_m_s: float = 0.5, window_s: float = 1.0) -> None:
        self.height_m = height_m
        self.altitude_tol_m = altitude_tol_m
        self.speed_tol_m_s = speed_tol_m_s
        self.window_s = window_s
        self._samples: list[tuple[float, float, float]] = []  # (time s, |altitude error| m, speed m/s)

    def update(self, time_s: float, altitude_m: float, speed_m_s: float) -> bool:
        """Feed one sample (vehicle time s, altitude m above home, speed m/s); True once settled."""
        if not (math.isfinite(time_s) and math.isfinite(altitude_m) and math.isfinite(speed_m_s)):
            return False
        if self._samples and time_s <= self._samples[-1][0]:
            return self.settled  # duplicated / reordered sample
        self._samples.append((time_s, abs(altitude_m - self.height_m), speed_m_s))
        while len(self._samples) > 1 and time_s - self._samples[1][0] >= self.window_s:
            self._samples.pop(0)
        return self.settled

    @property
    def settled(self) -> bool:
        s = self._samples
        if len(s) < 2 or s[-1][0] - s[0][0] < self.window_s:
            return False
        n = len(s)
        return sum(e for _, e, _ in s) / n <= self.altitude_tol_m and sum(v for _, _, v in s) / n <= self.speed_tol_m_s


@dataclass(frozen=True)
class EndSpec:
    """When path following ends (any that is set)."""

    laps: float | None = None
    duration_s: float | None = None  # vehicle time since activation
    open_path_end: bool = True  # stop at the end of an open path


def end_reason(
    spec: EndSpec,
    laps: float,
    elapsed_s: float,
    path_closed: bool,
    lam: float,
    lam_max: float,
    speed_ref_m_s: float,
    eta2_m_s: float,
) -> str:
    """Why following should end now ("" to continue). Pure."""
    if spec.laps is not None and laps >= spec.laps:
        return f"{spec.laps:g} laps done"
    if spec.duration_s is not None and elapsed_s >= spec.duration_s:
        return f"duration {spec.duration_s:g} s reached"
    if spec.open_path_end and not path_closed and math.isfinite(lam):
        at_end = lam >= lam_max - 1e-6 if speed_ref_m_s > 0 else lam <= 1e-6
        if at_end and abs(eta2_m_s) < 0.1:
            return "end of the open path reached"
    return ""
