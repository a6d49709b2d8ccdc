"""ArduPilot Copter: GUIDED, BRAKE / LAND; MAV_CMD_NAV_TAKEOFF; GUID_OPTIONS; jerk limits."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.dialects.base import Dialect, OffboardLoss, TakeoffOps
from pf_offboard.app.params import Parameters
from pf_offboard.app.profiles import ARDUPILOT
from pf_offboard.errors import InputError


class ArduPilotDialect(Dialect):
    profile = ARDUPILOT
    # GUIDED take-off: any setpoint would cancel it (the mode request alone holds it when safing)
    takeoff_streams_setpoints = False
    # GUIDED holds the take-off position by itself; LOITER would follow the RC throttle (with the
    # stick low, as in SITL without RC, it descends)
    holds_in_offboard_after_takeoff = True

    async def take_off(self, ops: TakeoffOps, height_m: float) -> None:
        """GUIDED, arm, MAV_CMD_NAV_TAKEOFF (ArduPilot ignores position targets on the ground).
        Nothing is sent meanwhile: in GUIDED any setpoint would cancel the take-off."""
        ops.send_nothing()
        await ops.engage_and_arm()
        ops.command(mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, height_m)

    async def ensure_output_requirements(self, params: Parameters, output_mode: str, allow_set: bool) -> None:
        """GUID_OPTIONS must have the bits the output mode needs; set them only if allowed."""
        required = self.profile.required_guid_options(output_mode)
        value = int(await params.read("GUID_OPTIONS"))
        if value & required == required:
            return
        missing = required & ~value
        if not allow_set:
            raise InputError(
                "--set-guid-options",
                f"ArduPilot GUID_OPTIONS={value} lacks bit(s) {missing} needed by --output {output_mode} "
                "(8: thrust as thrust; 16: no XY position correction); set them on the vehicle or pass --set-guid-options",
            )
        await params.write("GUID_OPTIONS", float(value | required), mavlink2.MAV_PARAM_TYPE_INT32)

    async def output_warnings(self, params: Parameters, output_mode: str) -> list[str]:
        if output_mode != "acceleration":
            return []
        jerk = min(await params.read("PSC_JERK_XY"), await params.read("PSC_JERK_Z"))
        if jerk < 20.0:
            return [f"ArduPilot jerk-limits acceleration targets (PSC_JERK_XY/Z = {jerk:g} m/s^3): "
                    "expect lag and, at high gains, oscillation; raise PSC_JERK_XY/Z or use --output rates"]  # fmt: skip
        return []

    async def offboard_loss(self, params: Parameters, output_mode: str, wanted: str | None) -> OffboardLoss:
        """ArduPilot stays in GUIDED when the targets stop: after GUID_TIMEOUT an acceleration /
        velocity target is dropped and it brakes to a hover; an attitude / rate target is replaced by
        level flight at constant altitude, which does not brake: the vehicle drifts (12 m in 20 s
        measured after the app was killed). No parameter makes it change mode: ``wanted`` is refused
        for attitude / rates."""
        timeout = await params.read("GUID_TIMEOUT")
        if output_mode == "acceleration":
            return OffboardLoss(f"ArduPilot keeps GUIDED; after GUID_TIMEOUT {timeout:g} s it brakes to a hover", drifts=False)
        text = (f"ArduPilot keeps GUIDED; after GUID_TIMEOUT {timeout:g} s it levels and holds altitude but does not brake: "
                "the vehicle drifts until a pilot or ground station takes over")  # fmt: skip
        if wanted is not None:
            raise InputError("--offboard-loss", f"{wanted} cannot be configured on ArduPilot with --output {output_mode}: {text}")
        return OffboardLoss(text, drifts=True)
