"""What the API hands back: a follow's result and progress samples. Pure data."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Progress:
    """One sample of :meth:`pf_offboard.Vehicle.status`.

    ``phase``: ``idle`` between flights, else the flight's (``takeoff``, ``waiting``,
    ``engaging``, ``following``, ``handing_back``, ``safing``, ``done``, ``taken_over``,
    ``failed``); ``mode``: the autopilot's mode as its HEARTBEAT says; ``eta1_m``: distance along
    the path; ``speed_m_s``: the vehicle's measured speed; ``cross_track_m``: distance to the path
    (None before the first controller step); ``laps``: laps done in this follow.
    """

    phase: str
    mode: str
    armed: bool
    eta1_m: float | None = None
    speed_m_s: float | None = None
    cross_track_m: float | None = None
    laps: float = 0.0
    time_s: float | None = None  # the state sample's (autopilot) time


@dataclass(frozen=True)
class FollowResult:
    """How one :meth:`~pf_offboard.Vehicle.follow` (or take-off) ended.

    ``exit_code`` is what ``pf-offboard fly`` exits with for the same ending (0: as asked).
    ``summary`` is the flight summary (:class:`pf_offboard.logs.summary.FlightSummary`; None when
    no controller step ran), ``log_dir`` where the logs went (None: not logged).
    """

    reason: str
    exit_code: int = 0
    laps: float = 0.0
    activation_time_s: float | None = None
    summary: Any | None = None
    log_dir: Path | None = None
    breach: Any | None = None  # pf_offboard.safety.Verdict when the envelope ended following
    breach_time_s: float | None = None
    link_counters: Any | None = None
    estimator: Any | None = field(default=None, repr=False)
    config: Any | None = field(default=None, repr=False)  # the config flown (a lat/lon path: in the local frame)
    flight: Any | None = field(default=None, repr=False, compare=False)  # the app's Flight (reports)

    @property
    def ok(self) -> bool:
        return self.exit_code == 0

    def _window(self, name: str) -> Any:
        return None if self.summary is None else getattr(self.summary, name)

    @property
    def cross_track_rms_m(self) -> float | None:
        """RMS distance to the path from activation + 8 s to the end (m), the window the README and
        the printed summary quote; None for a flight that followed for less than that."""
        w = self._window("settled")
        return None if w is None else w.cross_track_rms_m

    @property
    def speed_error_rms_m_s(self) -> float | None:
        """RMS error of the speed along the path, measured from the position's derivative (±0.1 s,
        on the path's tangent), from activation + 8 s to the end (m/s); None if shorter."""
        w = self._window("settled")
        return None if w is None else w.speed_error_rms_m_s

    @property
    def whole_cross_track_rms_m(self) -> float | None:
        """RMS distance to the path over the whole following, convergence included (m)."""
        w = self._window("whole")
        return None if w is None else w.cross_track_rms_m

    @property
    def whole_speed_error_rms_m_s(self) -> float | None:
        """RMS speed error (from the position) over the whole following, convergence included (m/s)."""
        w = self._window("whole")
        return None if w is None else w.speed_error_rms_m_s
