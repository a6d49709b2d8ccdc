"""PX4: OFFBOARD, AUTO.LOITER / AUTO.LAND; the take-off flown by us on position setpoints."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.dialects.base import Dialect, OffboardLoss, TakeoffOps
from pf_offboard.app.params import Parameters
from pf_offboard.app.profiles import PX4

# COM_OBL_RC_ACT: what PX4 does when the offboard setpoints stop for COM_OF_LOSS_T (without RC,
# the RC-mode actions 0-2 fall back to Return, as observed on PX4 SITL)
_LOSS_ACTIONS = {0: "AUTO.RTL (no RC: position mode falls back to Return, climbing to RTL_RETURN_ALT)",
                 1: "AUTO.RTL (no RC: altitude mode falls back to Return, climbing to RTL_RETURN_ALT)",
                 2: "AUTO.RTL (no RC: stabilized falls back to Return, climbing to RTL_RETURN_ALT)",
                 3: "AUTO.RTL (Return: climbs to RTL_RETURN_ALT, flies home, lands)", 4: "AUTO.LAND", 5: "AUTO.LOITER (holds position)",
                 6: "flight termination (motors off: the vehicle falls)", 7: "disarm (motors off: the vehicle falls)"}  # fmt: skip
_WANTED = {"hold": 5, "land": 4}


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

    async def offboard_loss(self, params: Parameters, output_mode: str, wanted: str | None) -> OffboardLoss:
        """PX4: COM_OF_LOSS_T seconds of the last setpoint, then COM_OBL_RC_ACT; ``wanted`` sets it."""
        if wanted is not None:
            await params.write("COM_OBL_RC_ACT", float(_WANTED[wanted]), mavlink2.MAV_PARAM_TYPE_INT32)
        timeout = await params.read("COM_OF_LOSS_T")
        action = int(await params.read("COM_OBL_RC_ACT"))
        what = _LOSS_ACTIONS.get(action, f"COM_OBL_RC_ACT {action} (unknown)")
        text = f"PX4 flies our last setpoint for COM_OF_LOSS_T {timeout:g} s, then COM_OBL_RC_ACT {action}: {what}"
        return OffboardLoss(text, drifts=action not in _LOSS_ACTIONS or action <= 3, falls=action in (6, 7))
