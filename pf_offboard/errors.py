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
