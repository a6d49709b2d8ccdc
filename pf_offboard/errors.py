"""Errors for bad input. Every one names the offending field and the reason.

The CLI turns any :class:`InputError` into one line on stderr and exit code 2,
so a bad config, way-point, flag or endpoint never reaches a vehicle.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input: ``field`` names what is wrong, ``reason`` says why."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class ConfigError(InputError):
    """A config file (YAML) value is missing, of the wrong type or out of range."""


class LinkError(RuntimeError):
    """The MAVLink link failed: no heartbeat, refused command, lost vehicle."""


# ---------------------------------------------------------------------------------- flight endings
# The API (pf_offboard.connect) raises these when a flight ends other than as asked; each carries
# the exit code ``pf-offboard fly`` uses for the same ending and the partial result.
class FlightError(RuntimeError):
    """A flight ended other than as asked. ``exit_code``: the CLI's; ``result``: the partial
    :class:`pf_offboard.FollowResult` (None when no flight had started)."""

    exit_code = 1

    def __init__(self, message: str, result: object | None = None) -> None:
        super().__init__(message)
        self.result = result


class LinkLost(FlightError, LinkError):
    """No HEARTBEAT, stale state, the link failed (exit 3)."""

    exit_code = 3


class CommandRefused(FlightError, LinkError):
    """The autopilot refused or did not confirm OFFBOARD / GUIDED, arming or the take-off (exit 3)."""

    exit_code = 3


class OperatorTakeover(FlightError):
    """The operator switched the mode away; the app stopped sending and did not re-engage (exit 4)."""

    exit_code = 4


class EnvelopeBreach(FlightError):
    """The flight envelope was left: following ended, the safe mode was requested (exit 5)."""

    exit_code = 5


class CrashDetected(FlightError):
    """The vehicle disarmed, landed or fell while commanded (exit 6)."""

    exit_code = 6


class AutopilotFailsafe(FlightError):
    """The autopilot's own failsafe (LAND / RTL) took over; the app stopped commanding (exit 7)."""

    exit_code = 7


class AnotherController(FlightError):
    """Another controller's setpoints reached the vehicle while we flew it (relayed on the link, or
    in the autopilot's echoed target): following ended, the hold requested until confirmed (exit 8)."""

    exit_code = 8


class FlightInterrupted(FlightError):
    """Stopped (Ctrl-C, a stop request) before following began (exit 130)."""

    exit_code = 130
