"""One dialect per autopilot family (see :mod:`.base`): :func:`dialect_for` picks it."""

from __future__ import annotations

from pf_offboard.app.dialects.ardupilot import ArduPilotDialect
from pf_offboard.app.dialects.base import Dialect, TakeoffOps
from pf_offboard.app.dialects.px4 import Px4Dialect
from pf_offboard.app.profiles import Autopilot, Profile

_DIALECTS: dict[Autopilot, type[Dialect]] = {Autopilot.PX4: Px4Dialect, Autopilot.ARDUPILOT: ArduPilotDialect}


def dialect_for(profile: Profile) -> Dialect:
    """The dialect of ``profile``'s autopilot family."""
    return _DIALECTS[profile.autopilot]()


__all__ = ["ArduPilotDialect", "Dialect", "Px4Dialect", "TakeoffOps", "dialect_for"]
