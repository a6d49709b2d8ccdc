"""PX4: OFFBOARD, AUTO.LOITER / AUTO.LAND; the take-off flown by us on position setpoints."""

from __future__ import annotations

from pf_offboard.app.dialects.base import Dialect, TakeoffOps
from pf_offboard.app.profiles import PX4


class Px4Dialect(Dialect):
    profile = PX4
    takeoff_streams_setpoints = True

    async def take_off(self, ops: TakeoffOps, height_m: float) -> None:
        """Fly the take-off ourselves in OFFBOARD: position setpoints (a hold where the vehicle
        stands) are the proof of life PX4 needs before it accepts the mode; then arm and raise
        the hold to the take-off height."""
        ops.hold_here()
        await ops.proof_of_life()
        await ops.engage_and_arm()
        ops.climb_to(height_m)
