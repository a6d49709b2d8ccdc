"""The phases of one flight and how each ends (exit codes, :class:`FlightResult`). Pure data.

Phases: ``preflight`` → (``takeoff``) → ``waiting`` (throw) / ``engaging`` → ``following`` →
``handing_back`` → ``done``; or ``taken_over`` (the operator switched the mode away, in any
phase once we asked for a mode: we stop sending at once and never re-engage), or ``safing`` (an
envelope breach, stale state, lost HEARTBEAT or a failure while we may be in control: only the
safe setpoint goes out while the safe mode is requested until the HEARTBEAT confirms it) →
``failed``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

# Exit codes of `pf-offboard fly` (documented in docs/app.md); the API's exceptions carry them.
EXIT_OK = 0
EXIT_INPUT = 2
EXIT_LINK = 3  # no heartbeat, refused command, lost telemetry
EXIT_TAKEOVER = 4  # the operator took the vehicle back; we yielded
EXIT_BREACH = 5  # the flight envelope was breached: following ended, safe mode requested
EXIT_CRASH = 6  # the vehicle disarmed, landed or fell while we commanded it
EXIT_FAILSAFE = 7  # the autopilot's own failsafe took over (LAND / RTL); the app stopped commanding
EXIT_CONTROLLER = 8  # another controller's setpoints reached the vehicle while we flew: hold requested
EXIT_INTERRUPTED = 130  # Ctrl-C before following began


class Phase(enum.Enum):
    PREFLIGHT = "preflight"
    TAKEOFF = "takeoff"
    WAITING = "waiting"  # throw launch: proof-of-life while the vehicle is carried / thrown
    ENGAGING = "engaging"  # mode switch to OFFBOARD / GUIDED requested, not yet confirmed
    FOLLOWING = "following"
    HANDING_BACK = "handing_back"
    SAFING = "safing"  # only the safe setpoint goes out; the safe mode is requested until confirmed
    DONE = "done"
    TAKEN_OVER = "taken_over"
    FAILED = "failed"


TERMINAL = (Phase.DONE, Phase.TAKEN_OVER, Phase.FAILED)
# a wait in one of these phases is cut short: the flight is ending another way
INTERRUPTING = (Phase.SAFING, *TERMINAL)


@dataclass
class FlightResult:
    exit_code: int
    reason: str
    activation_time_s: float | None = None
    laps: float = 0.0
    steps: int = 0
    breach: Any | None = None  # pf_offboard.safety.Verdict: what ended following, if the envelope did
    breach_time_s: float | None = None  # vehicle time of the last state sample when it was detected
