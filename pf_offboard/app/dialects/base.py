"""What every autopilot dialect provides, and what is the same on all of them.

A dialect is one autopilot family's way of doing things the shared code must not branch on:
its modes and their names (its :class:`~pf_offboard.app.profiles.Profile`), its take-off
sequence, the parameters each output mode needs read or set, and how a take-off may be held
while safing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from pf_offboard.app.hover import plausible_hover_thrust
from pf_offboard.app.params import Parameters
from pf_offboard.app.profiles import Profile, output_mode_refusal
from pf_offboard.errors import LinkError

class TakeoffOps(Protocol):
    """The flight's operations a dialect's take-off sequence is made of."""

    def hold_here(self) -> None:
        """Enter the take-off phase streaming a position hold at the current position."""

    def send_nothing(self) -> None:
        """Enter the take-off phase streaming nothing."""

    async def proof_of_life(self) -> None:
        """Wait until a few setpoints went out."""

    async def engage_and_arm(self) -> None:
        """Switch to OFFBOARD / GUIDED and arm (confirmed, within the readiness deadline)."""

    def climb_to(self, height_m: float) -> None:
        """Move the streamed position hold up to ``height_m`` above home."""

    def command(self, command: int, *params: float) -> None:
        """Send one COMMAND_LONG (not waited for)."""

class Dialect:
    """Shared behaviour; subclasses set :attr:`profile` and the take-off sequence."""

    profile: Profile
    # while taking off, a position hold may be streamed (and is the safe setpoint when safing)
    takeoff_streams_setpoints: bool = True
    # after a take-off alone (the API's takeoff()), the autopilot holds the vehicle in our mode
    # without a setpoint stream; False: it is handed to the hold mode instead
    holds_in_offboard_after_takeoff: bool = False

    @property
    def name(self) -> str:
        return self.profile.name

    def output_refusal(self, output_mode: str) -> str:
        """Why this output mode is refused by default on this autopilot ("" if it is not)."""
        return output_mode_refusal(self.profile, output_mode)

    async def take_off(self, ops: TakeoffOps, height_m: float) -> None:
        raise NotImplementedError

    async def read_setpoint_mapping(
        self, params: Parameters, output_mode: str, hover_thrust: float | None, encoder: Any, warn: Callable[[str], None]
    ) -> Any:
        """What the encoder needs to know of the autopilot's setpoint mapping; returns the encoder
        to fly with.

        attitude / rates: the hover thrust (unless the config gives one); a value no vehicle hovers
        at is a link error; whether the autopilot boosts the thrust by 1 / cos(tilt)
        (:attr:`Profile.thrust_angle_boost_param`, ArduPilot's ATC_ANGLE_BOOST; unanswered: its default, 1). acceleration: whether the autopilot tilts from g alone
        (:attr:`Profile.accel_tilt_param`, PX4's MPC_ACC_DECOUPLE); without an answer the profile's
        default (PX4's own default) is kept and a warning says so.
        """
        profile = self.profile
        if output_mode != "acceleration":
            if hover_thrust is None:
                hover = await params.read(profile.hover_thrust_param)
                if not plausible_hover_thrust(hover):
                    raise LinkError(f"{profile.hover_thrust_param} = {hover:g} is not a plausible hover thrust")
                encoder = encoder.with_hover_thrust(float(hover))
            if profile.thrust_angle_boost_param is not None:
                try:
                    boost = await params.read(profile.thrust_angle_boost_param)
                except LinkError as exc:
                    warn(f"pf-offboard: warning: {exc}; assuming {profile.thrust_angle_boost_param} = 1, the autopilot's default")
                    boost = 1.0
                encoder = encoder.with_thrust_angle_boost(boost != 0.0)
            return encoder
        if profile.accel_tilt_param is None:
            return encoder
        try:
            value = await params.read(profile.accel_tilt_param)
        except LinkError as exc:
            default = "1 (tilt from g alone)" if profile.accel_tilt_from_gravity else "0"
            warn(f"pf-offboard: warning: {exc}; assuming {profile.accel_tilt_param} = {default}, the autopilot's default")
            return encoder
        if value not in (0.0, 1.0):
            raise LinkError(f"{profile.accel_tilt_param} = {value:g} is neither 0 nor 1")
        return encoder.with_tilt_from_gravity(profile.tilts_from_gravity(value))

    async def read_tilt_limit(
        self, params: Parameters, output_mode: str, config_deg: float, warn: Callable[[str], None]
    ) -> float:
        """The tilt limit to plan and fly with (degrees): min(``config_deg``, the autopilot's).

        acceleration only (attitude / rate targets are flown as sent): the autopilot's limit from
        :attr:`Profile.accel_tilt_limit_params`; lower than the config's: a warning naming both.
        Unanswered: the config's, with a warning. NaN, <= 0 or > 90 degrees: LinkError naming the
        parameter.
        """
        names = self.profile.accel_tilt_limit_params
        if output_mode != "acceleration" or not names:
            return config_deg
        reported: dict[str, float] = {}
        for name, _deg_per_unit in names:
            try:
                reported[name] = float(await params.read(name))
            except LinkError as exc:
                warn(f"pf-offboard: warning: {exc}; planning with limits.max_tilt_deg = {config_deg:g} deg, "
                     "which the autopilot may clip")  # fmt: skip
                return config_deg
            try:
                autopilot_deg = self.profile.accel_tilt_limit_deg(reported)
            except ValueError as exc:
                raise LinkError(str(exc)) from None
            if autopilot_deg is not None:
                break
        assert autopilot_deg is not None
        if autopilot_deg < config_deg:
            warn(f"pf-offboard: warning: the autopilot's tilt limit ({name}) is {autopilot_deg:g} deg, below "
                 f"limits.max_tilt_deg = {config_deg:g} deg; planning and flying with {autopilot_deg:g} deg")  # fmt: skip
            return autopilot_deg
        return config_deg

    async def ensure_output_requirements(self, params: Parameters, output_mode: str, allow_set: bool) -> None:
        """Make sure the autopilot's parameters let it fly ``output_mode`` as we mean it, or refuse."""

    async def output_warnings(self, params: Parameters, output_mode: str) -> list[str]:
        """Warnings about how this autopilot will fly ``output_mode`` (parameters read)."""
        return []

    async def offboard_loss(self, params: Parameters, output_mode: str, wanted: str | None) -> OffboardLoss:
        """What the vehicle does if the app dies (its setpoints stop): read at connect, and with
        ``wanted`` ("hold" / "land") set where the autopilot can be told (InputError where it cannot)."""
        return OffboardLoss("unknown for this autopilot", drifts=False)


class OffboardLoss:
    """What the autopilot does when our setpoints stop: ``text`` for the user; ``drifts``: the
    vehicle is left flying with nothing holding its position; ``falls``: it stops its motors."""

    def __init__(self, text: str, drifts: bool, falls: bool = False) -> None:
        self.text = text
        self.drifts = drifts
        self.falls = falls

